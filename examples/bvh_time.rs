use firstshot::shadow_bvh::ShadowBvh;
use glam::Vec3;
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let scene = firstshot::scene::load(std::path::Path::new(&path)).unwrap();
    let patches = firstshot::scene::tessellate(&scene, scene.settings.patch_size).unwrap();
    let raster = firstshot::gpu::scene_buffers::raster_triangles(&patches);
    let bvh = ShadowBvh::build(&raster).unwrap();
    let y = Vec3::new(0.0, 3.97, 0.4);
    let pts: Vec<Vec3> = patches
        .patches
        .iter()
        .map(|p| {
            let c = (p.vertices[0] + p.vertices[1] + p.vertices[2]) / 3.0;
            Vec3::new(c.x as f32, c.y as f32, c.z as f32)
        })
        .collect();
    let t = std::time::Instant::now();
    let mut occ = 0;
    let (mut nv, mut nt) = (0u64, 0u64);
    for _ in 0..3 {
        for &x in &pts {
            let (o, a, b) = bvh.occluded_counted(y, x);
            occ += o as u32;
            nv += a;
            nt += b;
        }
    }
    let n = 3 * pts.len();
    println!(
        "{:.3} us/ray, occluded {:.2}, nodes/ray {:.1}, tris/ray {:.1}",
        t.elapsed().as_secs_f64() * 1e6 / n as f64,
        occ as f64 / n as f64,
        nv as f64 / n as f64,
        nt as f64 / n as f64
    );
}
