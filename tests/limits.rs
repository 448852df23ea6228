//! `render::check_limits`: a scene or an image that does not fit the device's limits is
//! refused before any GPU work, with `Error::Limits` (exit status 2) naming what is too big,
//! the limit, and the flag that fixes it. No GPU needed: the limits are made up.

mod common;

use firstshot::Error;
use firstshot::gpu::scene_buffers::{PAGED_ARRAYS, PATCH_STATE, PATCH_TABLE};
use firstshot::layout::{GpuPatchState, RasterVertex};
use firstshot::render::{RenderOptions, check_limits};
use firstshot::scene::{self, Patches};

/// The Cornell box, tessellated at its own patch size, with a 32 x 32 image.
fn cornell_box() -> (Patches, RenderOptions) {
    let scene = scene::load(&common::scenes::shipped("cornell_box")).expect("loads");
    let mut options = RenderOptions::from_scene(&scene);
    options.width = 32;
    options.height = 32;
    options.bundle_resolution = Some(64);
    options.hemicube_resolution = Some(64);
    let patches = scene::tessellate(&scene, options.patch_size).expect("tessellates");
    (patches, options)
}

/// wgpu's defaults, with the storage buffers per shader stage of lavapipe (the kernels bind
/// the pages of their per-patch arrays: more than wgpu's default of 8).
fn defaults() -> wgpu::Limits {
    wgpu::Limits { max_storage_buffers_per_shader_stage: 32, ..Default::default() }
}

/// `defaults` with every buffer and binding allowed `bytes`.
fn buffers_of(bytes: u64) -> wgpu::Limits {
    wgpu::Limits { max_storage_buffer_binding_size: bytes, max_buffer_size: bytes, ..defaults() }
}

/// `defaults` with every storage binding allowed `bytes` (buffers as large as wgpu's default).
fn bindings_of(bytes: u64) -> wgpu::Limits {
    wgpu::Limits { max_storage_buffer_binding_size: bytes, ..defaults() }
}

/// Asserts a `Error::Limits` refusal whose message holds every one of `parts`.
fn refused(result: firstshot::Result<()>, parts: &[&str]) {
    match result {
        Err(e @ Error::Limits(_)) => {
            assert!(e.is_usage(), "a limit is the user's to fix (exit status 2)");
            let message = e.to_string();
            for part in parts {
                assert!(message.contains(part), "{message:?} lacks {part:?}");
            }
        }
        other => panic!("expected Error::Limits with {parts:?}, got {other:?}"),
    }
}

/// The smallest binding that holds every paged per-patch array of `patches` (each in at
/// most its pages of whole patches), and the first array that needs it.
fn smallest_binding(patches: &Patches) -> (&'static str, u64) {
    let n = patches.patches.len() as u64;
    PAGED_ARRAYS
        .iter()
        .map(|a| (a.what, n.div_ceil(a.pages as u64) * a.bytes))
        .fold(("", 0), |a, b| if b.1 > a.1 { b } else { a })
}

#[test]
fn test01_the_cornell_box_fits_the_defaults() {
    let (patches, options) = cornell_box();
    assert!(patches.patches.len() > 1000, "a real scene: {} patches", patches.patches.len());
    check_limits(&defaults(), &patches, &options).expect("fits wgpu's default limits");
}

#[test]
fn test02_tiny_buffers_refuse_the_scene_and_name_the_fix() {
    let (patches, options) = cornell_box();
    refused(
        check_limits(&buffers_of(1024), &patches, &options),
        &["the patch table", "1024", "max_storage_buffer_binding_size", "--patch-size"],
    );
    // Either limit alone refuses it, and the message names the one that is small.
    let binding = bindings_of(4096);
    refused(check_limits(&binding, &patches, &options), &["max_storage_buffer_binding_size 4096", "--patch-size"]);
    let buffer = wgpu::Limits { max_buffer_size: 4096, ..defaults() };
    refused(check_limits(&buffer, &patches, &options), &["max_buffer_size 4096", "--patch-size"]);
}

#[test]
fn test03_the_per_patch_arrays_fit_their_pages_exactly_at_the_limit() {
    // The per-patch arrays are split over pages of whole patches, at most `pages` of them:
    // a binding of the largest page fits, one byte less takes a patch out of a page and
    // refuses the first array that needs it, naming the figures.
    let (patches, options) = cornell_box();
    // A grid whose lines' buckets (LINE_BUCKET fragments of 8 bytes a line) fit bindings this
    // small, so that the per-patch arrays are what the limit decides.
    let options = RenderOptions { bundle_resolution: Some(16), ..options };
    let n = patches.patches.len();
    let (largest, bytes) = smallest_binding(&patches);
    check_limits(&bindings_of(bytes), &patches, &options).expect("pages of exactly the limit fit");
    refused(
        check_limits(&bindings_of(bytes - 1), &patches, &options),
        &[&format!("{n} patches: {largest}"), &format!("a page at most {} bytes", bytes - 1), "--patch-size"],
    );
    // The same through the test knob that emulates a smaller device.
    let knob = RenderOptions { page_bytes: Some(bytes - 1), ..options.clone() };
    refused(check_limits(&defaults(), &patches, &knob), &[largest, "--patch-size"]);
    // The triangles are one vertex buffer, limited by the largest buffer only: the lattices'
    // triangles, not one a patch (90 for the Cornell box's 6 065 patches).
    let raster = firstshot::gpu::scene_buffers::raster_triangles(&patches);
    assert_eq!(raster.triangle_count() as u64, firstshot::gpu::scene_buffers::raster_triangle_count(&patches));
    assert!((raster.triangle_count() as usize) < n / 10, "{} triangles for {n} patches", raster.triangle_count());
    // Without its lattices every patch is a triangle of its own: a buffer one byte short of
    // them refuses the scene (the pages, 8 to an array, still fit).
    let unlattice = Patches { lattices: Vec::new(), ..patches.clone() };
    let triangles = n as u64 * 3 * size_of::<RasterVertex>() as u64;
    let buffer = wgpu::Limits { max_buffer_size: triangles - 1, ..defaults() };
    refused(check_limits(&buffer, &unlattice, &options), &["the rasterised triangles", "max_buffer_size"]);
    check_limits(&buffer, &patches, &options).expect("the lattices' triangles fit");
    // A device with too few storage buffers per stage for the pages cannot run the kernels.
    let few = wgpu::Limits { max_storage_buffers_per_shader_stage: 8, ..defaults() };
    refused(check_limits(&few, &patches, &options), &["storage buffers", "max_storage_buffers_per_shader_stage"]);
}

#[test]
fn test07_sixteen_storage_buffers_a_stage_run_a_scene_whose_arrays_fit_one_binding() {
    // wgpu's GL backend allows 16 storage buffers a shader stage, fewer than the kernels'
    // pages. Where every per-patch array fits one binding the kernels bind only their first
    // page (`Paging::Whole`), and every kernel fits in 16: the run goes ahead. Where the
    // arrays need pages (a smaller binding, emulated by the page knob), it is refused with
    // the fix.
    let (patches, options) = cornell_box();
    let gl = wgpu::Limits { max_storage_buffers_per_shader_stage: 16, ..defaults() };
    check_limits(&gl, &patches, &options).expect("one page per array: 16 storage buffers a stage suffice");
    for spec in firstshot::stages::SPECS {
        let whole = firstshot::gpu::bindings::storage_buffers(spec, firstshot::gpu::kernel::Paging::Whole);
        assert!(whole <= 16, "{} binds {whole} storage buffers with every array in one page", spec.stem);
    }
    let (_, bytes) = smallest_binding(&patches);
    let paged = RenderOptions { page_bytes: Some(bytes), ..options };
    refused(check_limits(&gl, &patches, &paged), &["storage buffers", "16 per shader stage", "--patch-size"]);
}

#[test]
fn test04_hand_made_patches() {
    // Two triangles: 2 patches x 128 bytes (the state) is the largest per-patch buffer.
    let t = |z: f64| [glam::DVec3::new(0.0, 0.0, z), glam::DVec3::new(1.0, 0.0, z), glam::DVec3::new(0.0, 1.0, z)];
    let patches = Patches {
        patches: [t(0.0), t(1.0)]
            .iter()
            .map(|&v| {
                let c = (v[1] - v[0]).cross(v[2] - v[0]);
                scene::Patch {
                    vertices: v,
                    normal: c.normalize(),
                    area: 0.5 * c.length(),
                    material: None,
                    emission: [1.0; 3],
                    kind: scene::PatchKind::Surface { surface: 0 },
                    twin: false,
                }
            })
            .collect(),
        ..Default::default()
    };
    let options = RenderOptions { width: 2, height: 2, iterations: 0, ..cornell_box().1 };
    // A page holds one patch at least: the largest per-patch element (the state's 144 bytes;
    // the patch table's 96 and the triangles' 96 are smaller) fits, a byte less holds none.
    let patch = size_of::<GpuPatchState>() as u64;
    assert_eq!(PAGED_ARRAYS.iter().map(|a| a.bytes).max(), Some(patch));
    assert_eq!(PATCH_STATE.capacity(patch), PATCH_STATE.pages as u64);
    assert_eq!(PATCH_TABLE.capacity(patch), 8);
    check_limits(&buffers_of(patch), &patches, &options).expect("fits exactly");
    refused(check_limits(&buffers_of(patch - 1), &patches, &options), &["the iteration state", "--patch-size"]);
}

#[test]
fn test05_an_image_wider_or_taller_than_a_texture_is_refused() {
    let (patches, options) = cornell_box();
    let options = RenderOptions { hemicube_resolution: Some(32), bundle_resolution: Some(32), ..options };
    let limits = wgpu::Limits { max_texture_dimension_2d: 32, ..defaults() };
    check_limits(&limits, &patches, &options).expect("32 x 32 fits a texture side of 32");
    for (width, height) in [(33, 32), (32, 33), (1000, 1)] {
        let o = RenderOptions { width, height, ..options.clone() };
        refused(
            check_limits(&limits, &patches, &o),
            &[&format!("{width}x{height}"), "largest texture side 32", "--width/--height"],
        );
    }
    // Within the texture side, an image sum beyond one binding is cut into bands of rows:
    // only a row (16 bytes a pixel) must fit one binding (here 1 MiB, a row of 65536).
    let wide = RenderOptions { width: 65536, height: 4096, ..options.clone() };
    let texture = 65536;
    let limits =
        wgpu::Limits { max_texture_dimension_2d: texture, max_storage_buffer_binding_size: 1 << 20, ..defaults() };
    check_limits(&limits, &patches, &wide).expect("one row fits a binding");
    assert_eq!(firstshot::stages::image_estimate::band_rows(&limits, 65536), 1);
    let limits = wgpu::Limits {
        max_texture_dimension_2d: texture,
        max_storage_buffer_binding_size: (1 << 20) - 1,
        ..defaults()
    };
    refused(check_limits(&limits, &patches, &wide), &["a row of the image", "--width"]);
    let limits = wgpu::Limits { max_storage_buffer_binding_size: 128 << 20, ..defaults() };
    assert_eq!(firstshot::stages::image_estimate::band_rows(&limits, 7680), 1092, "128 MiB / (7680 x 16 bytes)");
}

#[test]
fn test06_hemicube_and_bundle_resolutions_beyond_the_device() {
    let (patches, options) = cornell_box();
    let limits = wgpu::Limits { max_texture_dimension_2d: 64, ..defaults() };
    check_limits(&limits, &patches, &options).expect("64 fits a texture side of 64");

    let hemicube = RenderOptions { hemicube_resolution: Some(65), ..options.clone() };
    refused(check_limits(&limits, &patches, &hemicube), &["--hemicube-resolution 65", "64"]);
    // Without the first shot no hemicube is rendered.
    check_limits(&limits, &patches, &RenderOptions { first_shot: false, ..hemicube }).expect("no first shot");

    let bundle = RenderOptions { bundle_resolution: Some(65), ..options.clone() };
    refused(check_limits(&limits, &patches, &bundle), &["--bundle-resolution 65", "64"]);
    refused(
        check_limits(&limits, &patches, &RenderOptions { bundle_resolution: Some(2), ..options.clone() }),
        &["--bundle-resolution 2", "expected 4 to 64"],
    );
    // Without iterations no bundle is cast.
    check_limits(&limits, &patches, &RenderOptions { iterations: 0, ..bundle }).expect("no iteration");

    // A side the textures allow, but lines' buckets (LINE_BUCKET fragments of 8 bytes a line)
    // larger than any buffer: the case that reached wgpu as a validation panic from small
    // scenes.
    let wide = RenderOptions { bundle_resolution: Some(8192), ..options.clone() };
    let lines = firstshot::iteration::line_table_bytes(8192);
    assert_eq!(lines, 8 * firstshot::layout::LINE_BUCKET as u64 * 8192 * 8192);
    refused(
        check_limits(&buffers_of(lines - 1), &patches, &wide),
        &["the ray-bundle line table", "--bundle-resolution"],
    );
}
