//! `render::check_limits`: a scene or an image that does not fit the device's limits is
//! refused before any GPU work, with `Error::Limits` (exit status 2) naming what is too big,
//! the limit, and the flag that fixes it. No GPU needed: the limits are made up.

mod common;

use firstshot::Error;
use firstshot::layout::{GpuPatch, GpuPatchState, RasterVertex};
use firstshot::render::{RenderOptions, check_limits};
use firstshot::scene::{self, Patches};

/// The Cornell box, tessellated at its own patch size, with a 32 x 32 image.
fn cornell_box() -> (Patches, RenderOptions) {
    let scene = scene::load(&common::scenes::shipped("cornell_box")).expect("loads");
    let mut options = RenderOptions::from_scene(&scene);
    options.width = 32;
    options.height = 32;
    options.bundle_resolution = 64;
    options.hemicube_resolution = 64;
    let patches = scene::tessellate(&scene, options.patch_size).expect("tessellates");
    (patches, options)
}

/// wgpu's defaults with every buffer and binding allowed `bytes`.
fn buffers_of(bytes: u64) -> wgpu::Limits {
    wgpu::Limits { max_storage_buffer_binding_size: bytes, max_buffer_size: bytes, ..Default::default() }
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

/// The per-patch buffers that check_limits sizes, in the order it checks them.
fn scene_buffers(patches: &Patches) -> [(&'static str, u64); 3] {
    let n = patches.patches.len() as u64;
    [
        ("the patch table", n * size_of::<GpuPatch>() as u64),
        ("the rasterised triangles", n * 3 * size_of::<RasterVertex>() as u64),
        ("the iteration state", n * size_of::<GpuPatchState>() as u64),
    ]
}

#[test]
fn test01_the_cornell_box_fits_the_defaults() {
    let (patches, options) = cornell_box();
    assert!(patches.patches.len() > 1000, "a real scene: {} patches", patches.patches.len());
    check_limits(&wgpu::Limits::default(), &patches, &options).expect("fits wgpu's default limits");
}

#[test]
fn test02_tiny_buffers_refuse_the_scene_and_name_the_fix() {
    let (patches, options) = cornell_box();
    refused(
        check_limits(&buffers_of(1024), &patches, &options),
        &["the patch table", "1024", "max_storage_buffer_binding_size", "--patch-size"],
    );
    // Either limit alone refuses it, and the message names the one that is small.
    let binding = wgpu::Limits { max_storage_buffer_binding_size: 4096, ..Default::default() };
    refused(check_limits(&binding, &patches, &options), &["max_storage_buffer_binding_size 4096", "--patch-size"]);
    let buffer = wgpu::Limits { max_buffer_size: 4096, ..Default::default() };
    refused(check_limits(&buffer, &patches, &options), &["max_buffer_size 4096", "--patch-size"]);
}

#[test]
fn test03_the_largest_scene_buffer_fits_exactly_at_the_limit() {
    let (patches, options) = cornell_box();
    let buffers = scene_buffers(&patches);
    // The first of the largest is the one refused first.
    let (largest, bytes) = buffers.iter().fold(buffers[0], |a, &b| if b.1 > a.1 { b } else { a });
    check_limits(&buffers_of(bytes), &patches, &options).expect("a buffer of exactly the limit fits");
    refused(
        check_limits(&buffers_of(bytes - 1), &patches, &options),
        &[largest, &format!("needs {bytes} bytes"), &format!("allows {}", bytes - 1), "--patch-size"],
    );
}

#[test]
fn test04_hand_made_patches() {
    // Two triangles: 2 patches x 96 bytes is the largest per-patch buffer.
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
    let patch_table = 2 * size_of::<GpuPatch>() as u64;
    check_limits(&buffers_of(patch_table), &patches, &options).expect("fits exactly");
    refused(check_limits(&buffers_of(patch_table - 1), &patches, &options), &["the patch table", "--patch-size"]);
}

#[test]
fn test05_an_image_wider_or_taller_than_a_texture_is_refused() {
    let (patches, options) = cornell_box();
    let options = RenderOptions { hemicube_resolution: 32, bundle_resolution: 32, ..options };
    let limits = wgpu::Limits { max_texture_dimension_2d: 32, ..Default::default() };
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
    let limits = wgpu::Limits {
        max_texture_dimension_2d: texture,
        max_storage_buffer_binding_size: 1 << 20,
        ..Default::default()
    };
    check_limits(&limits, &patches, &wide).expect("one row fits a binding");
    assert_eq!(firstshot::stages::image_estimate::band_rows(&limits, 65536), 1);
    let limits = wgpu::Limits {
        max_texture_dimension_2d: texture,
        max_storage_buffer_binding_size: (1 << 20) - 1,
        ..Default::default()
    };
    refused(check_limits(&limits, &patches, &wide), &["a row of the image", "--width"]);
    let limits = wgpu::Limits { max_storage_buffer_binding_size: 128 << 20, ..Default::default() };
    assert_eq!(firstshot::stages::image_estimate::band_rows(&limits, 7680), 1092, "128 MiB / (7680 x 16 bytes)");
}

#[test]
fn test06_hemicube_and_bundle_resolutions_beyond_the_device() {
    let (patches, options) = cornell_box();
    let limits = wgpu::Limits { max_texture_dimension_2d: 64, ..Default::default() };
    check_limits(&limits, &patches, &options).expect("64 fits a texture side of 64");

    let hemicube = RenderOptions { hemicube_resolution: 65, ..options.clone() };
    refused(check_limits(&limits, &patches, &hemicube), &["--hemicube-resolution 65", "64"]);
    // Without the first shot no hemicube is rendered.
    check_limits(&limits, &patches, &RenderOptions { first_shot: false, ..hemicube }).expect("no first shot");

    let bundle = RenderOptions { bundle_resolution: 65, ..options.clone() };
    refused(check_limits(&limits, &patches, &bundle), &["--bundle-resolution 65", "64"]);
    refused(
        check_limits(&limits, &patches, &RenderOptions { bundle_resolution: 2, ..options.clone() }),
        &["--bundle-resolution 2", "expected 4 to 64"],
    );
    // Without iterations no bundle is cast.
    check_limits(&limits, &patches, &RenderOptions { iterations: 0, ..bundle }).expect("no iteration");

    // A side the textures allow, but a line table (4 bytes a line) larger than any buffer:
    // the case that reached wgpu as a validation panic from small scenes.
    let wide = RenderOptions { bundle_resolution: 8192, ..options.clone() };
    let lines = firstshot::iteration::line_table_bytes(8192);
    assert_eq!(lines, 4 * (8192 * 8192 + 1));
    refused(
        check_limits(&buffers_of(lines - 1), &patches, &wide),
        &["the ray-bundle line table", "--bundle-resolution"],
    );
}
