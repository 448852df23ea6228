//! The GPU host: adapters and devices (`context`), WGSL kernels (`kernel`) and what they bind
//! (`bindings`), and small buffer helpers (`buffers`). Stages in `crate::stages` build on these.

pub mod bindings;
pub mod buffers;
pub mod context;
pub mod frustum;
pub mod kernel;
pub mod profile;
pub mod scene_buffers;

pub use context::{AdapterChoice, AdapterSummary, Context};
