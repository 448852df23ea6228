//! One host module per WGSL kernel (`wgsl/<stem>.wgsl`): each owns its pipeline, buffers and
//! bind groups, and records into an encoder it is given; none submits or waits.

pub mod brdf_probe;
pub mod bundle_finalize;
pub mod bundle_reflect;
pub mod bundle_transfer;
pub mod bundle_visibility;
pub mod camera_item_buffer;
pub mod first_shot_reduce;
pub mod first_shot_table;
pub mod image_estimate;
pub mod light_window;
pub mod prefix_sum;

use crate::gpu::bindings::KernelSpec;

/// Every kernel's interface, one per stem of `gpu::kernel::KERNELS`; `tests/kernel_bindings.rs`
/// holds each against naga's reflection of its WGSL.
pub const SPECS: &[&KernelSpec] = &[
    &camera_item_buffer::SPEC,
    &image_estimate::SPEC,
    &light_window::SPEC,
    &brdf_probe::SPEC,
    &bundle_reflect::SPEC,
    &bundle_visibility::SPEC,
    &bundle_transfer::SPEC,
    &bundle_finalize::SPEC,
    &prefix_sum::SPEC,
    &first_shot_reduce::SPEC,
    &first_shot_table::SPEC,
];
