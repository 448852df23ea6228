//! The scene on the GPU: patches, materials, light samples, the triangles to rasterise and
//! the per-patch iteration state. Built once per render; stages bind what they need.

use super::bindings::{self, Binding, read};
use super::buffers;
use crate::layout::*;
use crate::scene::{MaterialKind, PatchKind, Patches, SampleKind, Scene};
use glam::DVec3;

/// GPU copies of the tessellated scene.
pub struct SceneBuffers {
    pub patch_count: u32,
    pub patches: wgpu::Buffer,
    pub materials: wgpu::Buffer,
    pub samples: wgpu::Buffer,
    pub sample_count: u32,
    /// Three `RasterVertex` per patch, in patch order.
    pub vertices: wgpu::Buffer,
    /// `GpuPatchState` per patch (J_j, win_j).
    pub state: wgpu::Buffer,
    /// The first-shot factors r_ij, sparse by patch (empty until the first shot ran).
    pub first_shot: FirstShotTable,
    /// Bounding sphere of all geometry and light samples.
    pub centre: DVec3,
    pub radius: f64,
}

/// The material table as the GPU sees it; the last entry is black (area-light patches).
pub fn gpu_materials(scene: &Scene) -> Vec<GpuMaterial> {
    let mut out: Vec<GpuMaterial> = scene
        .materials
        .iter()
        .map(|m| match m.kind {
            MaterialKind::Diffuse { albedo } => GpuMaterial {
                diffuse: [albedo[0], albedo[1], albedo[2], 0.0],
                specular: [0.0; 4],
                kind: MATERIAL_DIFFUSE,
                _pad: [0; 3],
            },
            MaterialKind::Phong { diffuse, specular, shininess } => GpuMaterial {
                diffuse: [diffuse[0], diffuse[1], diffuse[2], 0.0],
                specular: [specular[0], specular[1], specular[2], shininess],
                kind: if specular == [0.0; 3] { MATERIAL_DIFFUSE } else { MATERIAL_PHONG },
                _pad: [0; 3],
            },
        })
        .collect();
    out.push(GpuMaterial::zeroed());
    out
}

fn v4(v: DVec3, w: f64) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, w as f32]
}

/// The patch table. `first_shot`: whether area lights and the first-shot triangles of
/// emitting shapes are first-shot lights (their emission is then left out of the iteration)
/// or plain emitters.
pub fn gpu_patches(scene: &Scene, patches: &Patches, first_shot: bool) -> Vec<GpuPatch> {
    let black = scene.materials.len() as u32;
    patches
        .patches
        .iter()
        .map(|p| {
            let mut flags = 0;
            if p.twin {
                flags |= PATCH_TWIN;
            }
            if first_shot && matches!(p.kind, PatchKind::AreaLight { .. } | PatchKind::Emitter { .. }) {
                flags |= PATCH_FIRST_SHOT_LIGHT;
            }
            GpuPatch {
                v0: v4(p.vertices[0], p.area),
                v1: v4(p.vertices[1], 0.0),
                v2: v4(p.vertices[2], 0.0),
                normal: v4(p.normal, p.normal.dot(p.vertices[0])),
                emission: [p.emission[0], p.emission[1], p.emission[2], 0.0],
                material: p.material.unwrap_or(black),
                flags,
                light_pick_area: light_pick_area(patches, p, first_shot) as f32,
                _pad: 0,
            }
        })
        .collect()
}

/// T A_t for a patch of a first-shot emitting shape: the area that a direct-light pass's
/// point on its triangle side t stands for, T being the number of the shape's sides
/// (`direct_light.rs`); 0 for every other patch, and without first shot.
pub fn light_pick_area(patches: &Patches, p: &crate::scene::Patch, first_shot: bool) -> f64 {
    match p.kind {
        PatchKind::Emitter { emitter, side, .. } if first_shot => {
            let triangles = &patches.emitters[emitter as usize].triangles;
            triangles.len() as f64 * triangles[side as usize].area
        }
        _ => 0.0,
    }
}

/// Three vertices per patch with the patch id (and twin bit) for the rasterising stages.
pub fn raster_vertices(patches: &Patches) -> Vec<RasterVertex> {
    let mut out = Vec::with_capacity(patches.patches.len() * 3);
    for (i, p) in patches.patches.iter().enumerate() {
        let id = i as u32 | if p.twin { VERTEX_TWIN_BIT } else { 0 };
        for v in p.vertices {
            out.push(RasterVertex { position: [v.x as f32, v.y as f32, v.z as f32], patch: id });
        }
    }
    out
}

/// The light-sample table.
pub fn gpu_samples(patches: &Patches) -> Vec<GpuLightSample> {
    patches
        .samples
        .iter()
        .map(|s| GpuLightSample {
            position: v4(s.position, 0.0),
            normal: v4(
                match s.kind {
                    SampleKind::Point => DVec3::ZERO,
                    SampleKind::AreaVertex { normal } => normal,
                    SampleKind::Spot { axis, .. } => axis,
                    SampleKind::Directional { direction } => direction,
                },
                s.weight,
            ),
            strength: [s.strength[0], s.strength[1], s.strength[2], 0.0],
            kind: match s.kind {
                SampleKind::Point => LIGHT_POINT,
                SampleKind::AreaVertex { .. } => LIGHT_AREA,
                SampleKind::Spot { .. } => LIGHT_SPOT,
                SampleKind::Directional { .. } => LIGHT_DIRECTIONAL,
            },
            cone_scale: match s.kind {
                SampleKind::Spot { cone, .. } => cone.scale as f32,
                _ => 0.0,
            },
            cone_offset: match s.kind {
                SampleKind::Spot { cone, .. } => cone.offset as f32,
                _ => 0.0,
            },
            _pad: 0,
        })
        .collect()
}

/// Bounding sphere of the patches and light samples, never of zero radius.
pub fn bounding_sphere(patches: &Patches) -> (DVec3, f64) {
    let (centre, radius) = crate::scene::tessellate::scene_bounds(patches);
    (centre, radius.max(1e-9))
}

impl SceneBuffers {
    pub fn new(device: &wgpu::Device, scene: &Scene, patches: &Patches, first_shot: bool) -> SceneBuffers {
        let gpu = gpu_patches(scene, patches, first_shot);
        let samples = gpu_samples(patches);
        let (centre, radius) = bounding_sphere(patches);
        let none = wgpu::BufferUsages::empty();
        SceneBuffers {
            patch_count: gpu.len() as u32,
            patches: buffers::storage_init(device, "firstshot.scene.patches", &gpu, none),
            materials: buffers::storage_init(device, "firstshot.scene.materials", &gpu_materials(scene), none),
            samples: buffers::storage_init(device, "firstshot.scene.light_samples", &samples, none),
            sample_count: samples.len() as u32,
            vertices: buffers::storage_init(
                device,
                "firstshot.scene.vertices",
                &raster_vertices(patches),
                wgpu::BufferUsages::VERTEX,
            ),
            state: buffers::storage_zeroed(
                device,
                "firstshot.scene.patch_state",
                (gpu.len() * std::mem::size_of::<GpuPatchState>()) as u64,
                wgpu::BufferUsages::COPY_SRC,
            ),
            first_shot: FirstShotTable::empty(device, gpu.len() as u32),
            centre,
            radius,
        }
    }
}

use bytemuck::Zeroable;

/// The first-shot factors in compressed-row form: the entries of patch j are
/// `entries[offsets[j]..offsets[j + 1]]`, each (light sample index, bits of r_ij as f32),
/// in ascending sample order.
pub struct FirstShotTable {
    /// patch_count + 1 u32.
    pub offsets: wgpu::Buffer,
    /// vec2<u32> per stored pair.
    pub entries: wgpu::Buffer,
    /// vec4<f32> per patch: rgb sum_i S_i r_ij (all a diffuse patch needs).
    pub irradiance: wgpu::Buffer,
    pub entry_count: u32,
}

/// Bind group 1 of the kernels that evaluate first-shot radiance
/// (`wgsl/common/first_shot_table.wgsl`), in their `KernelSpec`s.
pub const FIRST_SHOT_TABLE_GROUP: &[Binding] = &[
    // Row starts, patches + 1.
    read::<u32>("fs_offsets"),
    // (sample, bits of r_ij).
    read::<[u32; 2]>("fs_entries"),
    read::<GpuLightSample>("samples"),
    // rgb sum_i S_i r_ij per patch.
    read::<[f32; 4]>("fs_irradiance"),
];

impl FirstShotTable {
    /// The table as bind group 1 (`FIRST_SHOT_TABLE_GROUP`) over `layout`, with the light
    /// samples it indexes.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        samples: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        bindings::bind_group(
            device,
            "firstshot.first_shot_table.bind_group",
            layout,
            FIRST_SHOT_TABLE_GROUP,
            &[
                ("fs_offsets", (&self.offsets).into()),
                ("fs_entries", (&self.entries).into()),
                ("samples", samples.into()),
                ("fs_irradiance", (&self.irradiance).into()),
            ],
        )
    }

    /// No light pairs: every patch's row is empty.
    pub fn empty(device: &wgpu::Device, patch_count: u32) -> Self {
        FirstShotTable {
            offsets: buffers::storage_zeroed(
                device,
                "firstshot.first_shot.offsets",
                4 * (patch_count as u64 + 1),
                wgpu::BufferUsages::COPY_SRC,
            ),
            entries: buffers::storage_zeroed(device, "firstshot.first_shot.entries", 16, wgpu::BufferUsages::COPY_SRC),
            irradiance: buffers::storage_zeroed(
                device,
                "firstshot.first_shot.irradiance",
                16 * patch_count as u64,
                wgpu::BufferUsages::COPY_SRC,
            ),
            entry_count: 0,
        }
    }
}
