//! The memory a run will take, predicted from the scene and the options before any GPU work
//! (`predict`), and the refusal of a run that cannot fit (`check`): bytes per patch, per
//! pixel, per bundle line, per fragment and per first-shot pair, the GPU buffers and the
//! host's own copies. On a CPU adapter (lavapipe) the GPU's buffers are host memory too.
//! `--stats` writes the prediction (`RenderStats::memory`) with the peak resident set the
//! run reached, docs/CLI.md.

use crate::gpu::scene_buffers::PAGED_ARRAYS;
use crate::layout::RasterVertex;
use crate::render::RenderOptions;
use crate::scene::{Patches, Scene};
use crate::{Error, Result};
use serde::Serialize;

/// GPU bytes per patch besides the paged arrays: the triangles (at most one a patch: 3
/// `RasterVertex` and 3 lattice words, `scene_buffers::raster_triangles`), the
/// first-shot row starts (4) and the copy of the state kept to redo a batch of steps
/// (`GpuPatchState`).
const OTHER_DEVICE_BYTES_PER_PATCH: u64 =
    3 * RASTER_VERTEX_BYTES + 4 + size_of::<crate::layout::GpuPatchState>() as u64;
/// GPU bytes per patch while the first shot runs: its 64-bit sums (8), row counts (4), fill
/// cursors (4) and prefix-sum scratch (4).
const FIRST_SHOT_BYTES_PER_PATCH: u64 = 20;
/// GPU bytes per first-shot pair: the list (vec4<u32>) and the table's entry (vec2<u32>).
const BYTES_PER_PAIR: u64 = 16 + 8;
/// GPU bytes per bundle line: its count and spill head (u32 each), its slice (2 u32) and its
/// bucket of `LINE_BUCKET` fragments.
const BYTES_PER_LINE: u64 = 16 + 8 * crate::layout::LINE_BUCKET as u64;
/// GPU bytes per fragment past the lines' buckets (the capacity): a spill node (16), a place
/// in a long line's slice (depth bits, patch: 8) and in the list of long lines (4).
const BYTES_PER_FRAGMENT: u64 = 28;
/// GPU bytes per pixel of a view: the image sum (two halves of vec4<f32>) and its copy kept
/// to redo a batch, the camera item buffer (patch id and depth, 4 bytes each; a supersampled
/// one's other texels are counted apart, `supersampled_camera_bytes`) and the gather's lists
/// of edge pixels and of senders' first bounces (8 each).
const DEVICE_BYTES_PER_PIXEL: u64 = 2 * 32 + 8 + 8 + 8;
/// Host bytes per pixel of a view: the image sum read back (32) and the image (rgba f32).
const HOST_BYTES_PER_PIXEL: u64 = 32 + 16;
/// Host bytes per patch while the scene is uploaded, besides the tessellated patch: the
/// patch table and the triangles built for the upload, and wgpu's staging copy of each, and
/// the pieces' bits (`scene_buffers::piece_bits`, 4 bytes). (`scene_buffers::smooth_edges`
/// takes about 100 bytes a patch before them, and returns it.)
const UPLOAD_BYTES_PER_PATCH: u64 = 2 * (96 + 3 * RASTER_VERTEX_BYTES) + 4;
/// A rasterised vertex: its `RasterVertex` and its lattice word.
const RASTER_VERTEX_BYTES: u64 = (size_of::<RasterVertex>() + size_of::<u32>()) as u64;
/// The process without a scene: code, the adapter's own allocations, the shaders (a 64 x 64
/// render of the Cornell box peaks at 160 MiB resident on lavapipe).
const BASE_BYTES: u64 = 128 << 20;

/// The prediction (`--stats`: `memory`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct MemoryPlan {
    pub patches: u64,
    /// GPU bytes per patch for the whole run (paged arrays, triangles, state copy).
    pub device_bytes_per_patch: u64,
    /// Host bytes per patch: the tessellated patch, and the upload's copies (transient).
    pub host_bytes_per_patch: u64,
    pub pixels: u64,
    pub device_bytes_per_pixel: u64,
    pub host_bytes_per_pixel: u64,
    /// Bundle lines (resolution squared, plus the coarse burn-in's; 0 without an iteration).
    pub lines: u64,
    /// Fragments the lists are first sized for, the coarse burn-in's included (each grows if a
    /// step needs more).
    pub fragments: u64,
    pub bytes_per_fragment: u64,
    /// First-shot pairs the list is first sized for (it grows if the first shot finds more).
    pub first_shot_pairs: u64,
    pub bytes_per_pair: u64,
    /// Texels of the shadow atlases at most, 8 bytes each.
    pub shadow_texels: u64,
    /// GPU memory, all buffers and textures together.
    pub device_bytes: u64,
    /// Host memory of the process itself (its own copies, the base of the process).
    pub host_bytes: u64,
    /// What must fit in the host's memory: `host_bytes`, plus `device_bytes` where the GPU's
    /// memory is the host's (a CPU adapter).
    pub total_host_bytes: u64,
    /// The host's available memory (`MemAvailable` of /proc/meminfo) when the run began, or
    /// the limit given (`--memory-limit`); `None` where unknown.
    pub available_bytes: Option<u64>,
    /// The most resident memory the process reached (VmHWM of /proc/self/status), at the end
    /// of the run; `None` before it or where unknown.
    pub peak_rss_bytes: Option<u64>,
}

/// The first capacity for the fragments past the lines' buckets (the spill list and the long
/// lines' slices) of a step at `resolution` over the bounding sphere of `radius`:
/// `options.bundle_capacity` where set (tests), else an eighth of the lines (at least
/// 1024), at most the geometric bound of all fragments and what one binding holds. A step
/// that needs more has its batch redone with twice the room (`render`); more than a binding
/// holds is refused then. (The bundled scenes spill a few thousand fragments a step:
/// Sierpinski at 704, 0.5 M fragments on 0.5 M lines, at most 9 000 of them in long lines.)
pub fn initial_fragment_capacity(
    options: &RenderOptions,
    limits: &wgpu::Limits,
    patches: &Patches,
    radius: f64,
    resolution: u32,
) -> u64 {
    options.bundle_capacity.unwrap_or_else(|| {
        let lines = resolution as u64 * resolution as u64;
        let bound = crate::iteration::fragment_bound(patches, radius, resolution);
        bound.min((lines / 8).max(1024)).min(crate::iteration::max_capacity(limits, resolution))
    })
}

/// The most first-shot pairs a device holds, the list in pages of at most `page_bytes`
/// (`scene_buffers::FIRST_SHOT_PAIRS`) and the table's entries (8 bytes a pair) in one binding.
pub fn max_pairs(limits: &wgpu::Limits, page_bytes: u64) -> u64 {
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    crate::gpu::scene_buffers::FIRST_SHOT_PAIRS.capacity(page_bytes).min(binding / 8)
}

/// The first capacity of the first shot's pair list (`first_shot::run`).
pub fn initial_pair_capacity(limits: &wgpu::Limits, page_bytes: u64, patches: u64, samples: u64) -> u64 {
    (patches * samples).clamp(1, 1 << 22).min(max_pairs(limits, page_bytes))
}

/// The memory of a render of `patches` with `options` on a device with `limits`;
/// `cpu_adapter`: the GPU's memory is the host's. `available`: what the host has.
pub fn predict(
    scene: &Scene,
    patches: &Patches,
    options: &RenderOptions,
    limits: &wgpu::Limits,
    cpu_adapter: bool,
    available: Option<u64>,
) -> MemoryPlan {
    let n = patches.patches.len() as u64;
    let paged: u64 = PAGED_ARRAYS.iter().map(|a| a.bytes).sum();
    let device_bytes_per_patch = paged + OTHER_DEVICE_BYTES_PER_PATCH;
    // The tessellated patch, and at most one `Piece` a patch (one per split polygon).
    let host_bytes_per_patch =
        (size_of::<crate::scene::Patch>() + size_of::<crate::scene::Piece>()) as u64 + UPLOAD_BYTES_PER_PATCH;
    let views = options.views(scene);
    let pixels = options.view_pixels(scene);
    // A supersampled camera item buffer's texels past one a pixel (id and depth, 8 bytes).
    let supersampled_camera_bytes: u64 = views
        .iter()
        .map(|v| {
            let s = options.camera_supersample_for(&v.camera) as u64;
            v.camera.width as u64 * v.camera.height as u64 * (s * s - 1) * 8
        })
        .sum();
    let (lines, fragments) = match options.iterations {
        0 => (0, 0),
        _ => {
            let (resolution, per_step) = options.bundles_for(scene, patches);
            let r = resolution as u64;
            let radius = crate::gpu::scene_buffers::bounding_sphere(patches).1;
            let capacity = |resolution| initial_fragment_capacity(options, limits, patches, radius, resolution);
            // The coarse burn-in's lines and fragments live beside the full grid's while it runs.
            let burn_in = crate::render::longest_burn_in_steps(scene, options, per_step);
            let (coarse_lines, coarse_fragments) = crate::iteration::coarse_burn_in(resolution, burn_in, per_step)
                .map_or((0, 0), |(c, _)| (c as u64 * c as u64, capacity(c)));
            (r * r + coarse_lines, capacity(resolution) + coarse_fragments)
        }
    };
    let first_shot_pairs = match options.first_shot {
        true => {
            let page = crate::gpu::scene_buffers::page_bytes(limits, options.page_bytes);
            initial_pair_capacity(limits, page, n, patches.samples.len() as u64)
        }
        false => 0,
    };
    // Resolved once: the automatic choice is a median over the patches for every light
    // sample, and the lights' windows take it as their floor.
    let hemicube_resolution = options.hemicube_resolution_for(patches);
    let hemicube = match options.first_shot {
        true => hemicube_resolution as u64 * hemicube_resolution as u64 * 8,
        false => 0,
    };
    // The lights' windows: six faces a light at most (a hemicube's five, packed), a sun's
    // parallel view 16 (`direct_light::SUN_VIEW_SCALE`), within the atlases' budget.
    let side = crate::direct_light::shadow_resolution(scene, patches, options, hemicube_resolution) as u64;
    let face = side * side;
    let suns = scene.lights.iter().filter(|l| matches!(l, crate::scene::Light::Directional { .. })).count() as u64;
    let shadow_texels =
        crate::direct_light::SHADOW_TEXEL_BUDGET.min(face * (6 * scene.lights.len() as u64 + 10 * suns));
    // The shadow rays' BVH (`shadow_bvh`), where area lights or emitting shapes take rays or
    // the gather asks pixels' rays for the environment (`direct_light::wants_shadow_bvh`): a
    // triangle (48 bytes) and at most two nodes (16 bytes each) a rasterised triangle, and a
    // word a patch for the lights it sees past every occluder (`direct_light::ShaftJob`).
    // The windows' texels above stay counted: a BVH that does not fit falls back to them.
    let shadow_bvh_bytes = match options.light_visibility {
        crate::direct_light::LightVisibility::Rays
            if crate::direct_light::wants_shadow_bvh(scene, patches, options.first_shot) =>
        {
            crate::gpu::scene_buffers::raster_triangle_count(patches) * (48 + 2 * 16) + n * 4
        }
        _ => 0,
    };
    let device_bytes = n * (device_bytes_per_patch + FIRST_SHOT_BYTES_PER_PATCH)
        + pixels * DEVICE_BYTES_PER_PIXEL
        + supersampled_camera_bytes
        + lines * BYTES_PER_LINE
        + fragments * BYTES_PER_FRAGMENT
        + first_shot_pairs * BYTES_PER_PAIR
        + hemicube
        + shadow_texels * 8
        + shadow_bvh_bytes;
    let host_bytes = BASE_BYTES + n * host_bytes_per_patch + pixels * HOST_BYTES_PER_PIXEL;
    MemoryPlan {
        patches: n,
        device_bytes_per_patch,
        host_bytes_per_patch,
        pixels,
        device_bytes_per_pixel: DEVICE_BYTES_PER_PIXEL,
        host_bytes_per_pixel: HOST_BYTES_PER_PIXEL,
        lines,
        fragments,
        bytes_per_fragment: BYTES_PER_FRAGMENT,
        first_shot_pairs,
        bytes_per_pair: BYTES_PER_PAIR,
        shadow_texels,
        device_bytes,
        host_bytes,
        total_host_bytes: host_bytes + if cpu_adapter { device_bytes } else { 0 },
        available_bytes: available,
        peak_rss_bytes: None,
    }
}

fn mib(bytes: u64) -> String {
    format!("{:.0} MiB", bytes as f64 / (1u64 << 20) as f64)
}

impl MemoryPlan {
    /// One line for the run summary.
    pub fn summary(&self) -> String {
        let available = self.available_bytes.map(|a| format!(", {} available", mib(a))).unwrap_or_default();
        format!(
            "memory: about {} on the host{available} (GPU {}: {} B a patch x {}, {} B a pixel x {}, {} fragments x {} B, {} first-shot pairs x {} B)",
            mib(self.total_host_bytes),
            mib(self.device_bytes),
            self.device_bytes_per_patch,
            self.patches,
            self.device_bytes_per_pixel,
            self.pixels,
            self.fragments,
            self.bytes_per_fragment,
            self.first_shot_pairs,
            self.bytes_per_pair
        )
    }

    /// Refuses, before any GPU work, a run whose predicted host memory exceeds what is
    /// available, with the figures and what to change.
    pub fn check(&self) -> Result<()> {
        let Some(available) = self.available_bytes else { return Ok(()) };
        if self.total_host_bytes <= available {
            return Ok(());
        }
        let patches = self.patches * (self.device_bytes_per_patch + self.host_bytes_per_patch);
        let pixels = self.pixels * (self.device_bytes_per_pixel + self.host_bytes_per_pixel);
        let mut hint = if patches >= pixels {
            "use a larger --patch-size (or a coarser tessellation)".to_string()
        } else {
            "use a smaller --width/--height".to_string()
        };
        if self.fragments > 0 {
            hint.push_str(", or a smaller --bundle-resolution");
        }
        Err(Error::Limits(format!(
            "the run needs about {} of host memory, {} are available (MemAvailable, or --memory-limit): {} patches ({} B a patch, {} in all), {} pixels ({} B a pixel, {} in all), {} fragments ({}); {hint}",
            mib(self.total_host_bytes),
            mib(available),
            self.patches,
            self.device_bytes_per_patch + self.host_bytes_per_patch,
            mib(patches),
            self.pixels,
            self.device_bytes_per_pixel + self.host_bytes_per_pixel,
            mib(pixels),
            self.fragments,
            mib(self.fragments * self.bytes_per_fragment)
        )))
    }
}

/// `MemAvailable` of /proc/meminfo in bytes; `None` where there is none.
pub fn host_available() -> Option<u64> {
    meminfo_field(&std::fs::read_to_string("/proc/meminfo").ok()?, "MemAvailable:")
}

/// The peak resident set of this process (VmHWM of /proc/self/status) in bytes.
pub fn peak_rss() -> Option<u64> {
    meminfo_field(&std::fs::read_to_string("/proc/self/status").ok()?, "VmHWM:")
}

/// A "NAME:   1234 kB" field in bytes.
fn meminfo_field(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let kib: u64 = line[name.len()..].trim().trim_end_matches("kB").trim().parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meminfo_fields_parse() {
        let text = "MemTotal:       24576000 kB\nMemAvailable:   20000000 kB\n";
        assert_eq!(meminfo_field(text, "MemAvailable:"), Some(20_000_000 * 1024));
        assert_eq!(meminfo_field(text, "VmHWM:"), None);
    }

    fn plan(patches: u64, pixels: u64, available: Option<u64>) -> MemoryPlan {
        let device = patches * 364 + pixels * 72;
        let host = patches * 432 + pixels * 48;
        MemoryPlan {
            patches,
            device_bytes_per_patch: 364,
            host_bytes_per_patch: 432,
            pixels,
            device_bytes_per_pixel: 72,
            host_bytes_per_pixel: 48,
            lines: 0,
            fragments: 0,
            bytes_per_fragment: 8,
            first_shot_pairs: 0,
            bytes_per_pair: 24,
            shadow_texels: 0,
            device_bytes: device,
            host_bytes: host,
            total_host_bytes: device + host,
            available_bytes: available,
            peak_rss_bytes: None,
        }
    }

    #[test]
    fn a_plan_fits_up_to_the_available_memory_and_is_refused_past_it() {
        let p = plan(1000, 10, None);
        assert!(p.check().is_ok(), "unknown memory refuses nothing");
        let total = p.total_host_bytes;
        assert!(plan(1000, 10, Some(total)).check().is_ok(), "exactly what is available fits");
        let e = plan(1000, 10, Some(total - 1)).check().unwrap_err();
        assert!(e.is_usage() && e.to_string().contains("--patch-size"), "{e}");
        let e = plan(10, 1_000_000, Some(1 << 20)).check().unwrap_err();
        assert!(e.to_string().contains("--width/--height") && !e.to_string().contains("--bundle-resolution"), "{e}");
    }
}
