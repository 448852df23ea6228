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
