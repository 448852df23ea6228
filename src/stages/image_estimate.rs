//! Image estimate (`wgsl/image_estimate.wgsl`): adds one estimate of every camera pixel to
//! the running sums of the image: emission and per-pixel direct light (`record_direct`) to
//! the first half, the indirect light gathered through the step's bundle (`record_gather`)
//! to the second. The image is the sum of the two halves' means (`read_mean`).

use crate::direct_light::DirectLights;
use crate::gpu::bindings::{Kernel, KernelSpec, compute, read, read_write, uint_texture, uniform};
use crate::gpu::scene_buffers::SceneBuffers;
use crate::gpu::{buffers, kernel};
use crate::iteration::GatherBuffers;
use crate::layout::{GpuBundle, GpuCamera, GpuDirectLight, GpuEstimateParams, GpuMaterial, GpuPatch, GpuWindowFace};
use crate::stages::camera_item_buffer::CameraItemBuffer;
use crate::{Error, Result};

pub const SPEC: KernelSpec = KernelSpec {
    stem: "image_estimate",
    visibility: wgpu::ShaderStages::COMPUTE,
    // `direct`, `gather`: one invocation per pixel; `gather_edges`, `gather_first_bounce`: a
    // fixed grid of `list_workgroups`.
    entry_points: &[
        compute("direct", [8, 8, 1]),
        compute("gather", [8, 8, 1]),
        compute("gather_edges", [64, 1, 1]),
        compute("gather_first_bounce", [64, 1, 1]),
    ],
    groups: &[
        &[
            uniform::<GpuCamera>("camera"),
            uniform::<GpuEstimateParams>("params"),
            // Patch index + 1 per pixel.
            uint_texture("item_buffer"),
            read::<GpuPatch>("patches").paged(crate::gpu::scene_buffers::PATCH_TABLE.pages),
            read::<GpuMaterial>("materials"),
            // One half of the image sum, rgb sum and w count per pixel: Le + D for the
            // `direct` entry point, G for `gather` (each half its own buffer, bound in its
            // own group 0, so that each needs only 16 bytes a pixel of one binding). One
            // pixel per invocation: no race.
            read_write::<[f32; 4]>("image_sum"),
            // The band's pixels whose gather needs the nearest surface on the line (x near
            // its patch's edge): [0] their count, then per pixel its index and its place on
            // its line; `gather` lists them, `gather_edges` estimates them.
            read_write::<u32>("edges"),
            // Each material's glossy-lobe albedo table (`scene_buffers::gpu_glossy_albedo`):
            // the control variate of the gather's glossy part.
            read::<f32>("glossy_albedo"),
            // The band's pixels whose sender is near (docs/ALGORITHM.md 6): [0] their count,
            // then per pixel its index and the sender's id; `gather` and `gather_edges` list
            // them, `gather_first_bounce` evaluates the sender's first bounce per point.
            read_write::<u32>("near_senders"),
        ],
        // The direct light (`direct_light::DirectLights`).
        &[
            read::<GpuDirectLight>("lights"),
            read::<GpuWindowFace>("faces"),
            // Faces with tile.w == 0: the point lights' kept cubes.
            uint_texture("kept_atlas"),
            // Faces with tile.w == 1: the area lights' windows of this pass.
            uint_texture("pass_atlas"),
            // The shadow rays' BVH of the scene's triangles (`shadow_bvh`), where the area
            // lights take rays instead of windows (SHADOW_RAYS).
            read::<crate::layout::GpuBvhNode>("shadow_nodes"),
            read::<crate::layout::GpuBvhTriangle>("shadow_triangles"),
            // A word a patch: bit i where the patch sees all of area light i past every
            // occluder (`direct_light::ShaftJob`), so its pixels cast no shadow ray to it.
            read::<u32>("unshadowed"),
        ],
        // The gather (`iteration::GatherBuffers`), after the step's transfer sorted its lines.
        &[
            // As a storage buffer, not a uniform: lavapipe builds uniform values that steer a
            // kernel's code into variants, compiled at dispatch, and `gather` was compiled
            // again at every step of a new seed where the scene has no first shot
            // (docs/PERFORMANCE.md, "A longer glossy history").
            read::<GpuBundle>("bundle"),
            // Surfaces per line, resolution^2: a line's bucket holds them up to LINE_BUCKET.
            read::<u32>("counts"),
            // (begin, end) of each longer line's slice of `fragments`, resolution^2.
            read::<[u32; 2]>("slices"),
            // (depth bits, patch | FRAGMENT_FRONT_BIT), each line's slice sorted by depth.
            read::<[u32; 2]>("fragments"),
            // What each patch sends the image this step, and its Lbar_j before this step, the
            // control variate of the gather at its pixels (`bundle_reflect`'s image_senders).
            read::<crate::layout::GpuImageSender>("image_senders")
                .paged(crate::gpu::scene_buffers::IMAGE_SENDERS.pages),
        ],
    ],
};

/// The bytes per pixel of each half of the image sum (vec4<f32>: rgb sum, w count).
pub const IMAGE_SUM_BYTES_PER_PIXEL: u64 = 16;

/// Rows per band of the image sum for an image `width` pixels wide: as many as one storage
/// binding (and one buffer) of the device holds, so an image of any size within the
/// device's memory is summed, in as few dispatches as the limit allows.
pub fn band_rows(limits: &wgpu::Limits, width: u32) -> u32 {
    let most = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    let rows = most / (u64::from(width.max(1)) * IMAGE_SUM_BYTES_PER_PIXEL);
    rows.clamp(1, u64::from(u32::MAX)) as u32
}

/// One band of whole image rows: its part of both halves of the image sum, each a buffer
/// that one storage binding can hold, and the parameters that say where it starts.
struct Band {
    first_row: u32,
    rows: u32,
    params: wgpu::Buffer,
    /// Le + D, then G.
    sums: [wgpu::Buffer; 2],
    /// The gather's list of pixels left to `gather_edges` (a count, then two u32 a pixel).
    edges: wgpu::Buffer,
    /// The gathers' list of pixels with a near sender (a count, then two u32 a pixel).
    near_senders: wgpu::Buffer,
    /// Group 0 for `direct` (binding `sums[0]`) and for `gather` (`sums[1]`).
    groups: [wgpu::BindGroup; 2],
}

/// Pipelines, parameters and the image sum (two halves of vec4<f32> per pixel: rgb sum,
/// w count; Le + D, then G), in bands of rows so that no binding exceeds the device's limit.
pub struct ImageEstimate {
    /// The render's, shared by its views (`ImagePipelines::build`).
    pipelines: ImagePipelines,
    bands: Vec<Band>,
    direct_group: wgpu::BindGroup,
    gather_group: wgpu::BindGroup,
    width: u32,
    height: u32,
    /// 1, or 2 when a step has four bundles and each gathers one pixel of every 2 x 2
    /// (`iteration::pixel_stride`): the gather's grid is this much smaller on each side.
    pixel_stride: u32,
}

/// How `gather` finishes the pixels near their patch's edge and those with a near sender:
/// inline (`FUSED_GATHER` in `wgsl/image_estimate.wgsl`: one dispatch a gather), or by
/// listing them for `gather_edges` and `gather_first_bounce` (two lists cleared and three
/// dispatches a gather). The image is the same either way, up to the order of its float sums.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GatherPasses {
    Fused,
    /// The list passes on a fixed grid of this many workgroups (`list_workgroups`).
    Split {
        list_workgroups: u32,
    },
}

impl GatherPasses {
    /// "fused" or "split", as `--gather` and the run's statistics name them.
    pub fn name(self) -> &'static str {
        match self {
            GatherPasses::Fused => "fused",
            GatherPasses::Split { .. } => "split",
        }
    }
}

/// One pass of a view's gather on a step (`ImageEstimate::gather_passes`).
enum GatherPass<'a> {
    /// `gather` over the band's pixels; `edges`, `near_senders`: it lists pixels for the
    /// passes after it (split), whose lists' counts it clears first.
    Main { edges: bool, near_senders: bool },
    /// A pass over one of those lists (`gather_edges`, `gather_first_bounce`), on a fixed grid
    /// of `workgroups` (the list's length is known only on the GPU); `label` its dispatch's.
    List { name: &'static str, label: &'static str, pipeline: &'a wgpu::ComputePipeline, workgroups: u32 },
}

impl GatherPass<'_> {
    fn name(&self) -> &'static str {
        match self {
            GatherPass::Main { .. } => "gather",
            GatherPass::List { name, .. } => name,
        }
    }
}

/// Which of `GatherPasses` a run asks for (`--gather`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum GatherChoice {
    /// `fused_gather`'s rule for the adapter.
    #[default]
    Auto,
    Fused,
    Split,
}

/// The gather's passes on `adapter`: split on a CPU adapter, fused on any other (unless
/// `choice` says). Lavapipe runs a shader 8 lanes to a vector and pays for a branch whenever
/// one lane takes it, so there the few pixels near an edge or a near sender cost least in
/// passes of their own (the split took a fifth off the Cornell box's gather, docs/
/// PERFORMANCE.md). A GPU pays instead for each pass of every view's step: a dispatch, a
/// barrier and the host's recording of both (docs/PERFORMANCE.md, "The gather in one pass on
/// a GPU").
pub fn fused_gather(adapter: &crate::gpu::AdapterSummary, choice: GatherChoice) -> GatherPasses {
    let split = GatherPasses::Split { list_workgroups: list_workgroups(adapter) };
    match choice {
        GatherChoice::Fused => GatherPasses::Fused,
        GatherChoice::Split => split,
        GatherChoice::Auto if adapter.is_cpu() => split,
        GatherChoice::Auto => GatherPasses::Fused,
    }
}

/// Workgroups (of 64) of `gather_edges` and `gather_first_bounce`, which stride over the
/// pixels the gather listed: a fixed grid, since the lists' lengths are known only on the
/// GPU. A GPU needs many for lists of thousands of pixels; a CPU adapter runs a workgroup
/// at a time on each core, and there every workgroup that loops over nothing still costs
/// its start: with 64, `gather_first_bounce` over an empty list took 1.7 ms of its 2.7-3.2
/// ms on lavapipe, with 8 it took 1.9 ms in all (docs/PERFORMANCE.md, "Near senders' first
/// bounce").
pub fn list_workgroups(adapter: &crate::gpu::AdapterSummary) -> u32 {
    if adapter.is_cpu() { 8 } else { 64 }
}

/// The image estimate's kernel and pipelines. They depend on the scene's paging, materials and
/// lights, not on a camera: every view of a render shares them, and `Renderer::new` builds
/// them beside the first shot.
#[derive(Clone)]
pub struct ImagePipelines {
    built: Kernel,
    direct: wgpu::ComputePipeline,
    gather: wgpu::ComputePipeline,
    /// `gather_edges`, where the gather's passes are split.
    edges: Option<wgpu::ComputePipeline>,
    /// `gather_first_bounce`, where the gathers list near senders (`first_bounce_per_point`).
    first_bounce: Option<wgpu::ComputePipeline>,
    /// How a gather's pixels are finished (`fused_gather`).
    passes: GatherPasses,
}

impl ImagePipelines {
    /// `paging` and `scene_constants`: `SceneBuffers::paging` and `SceneBuffers::constants`
    /// (the code of what the scene lacks left out: glossy materials, shared emitting shapes).
    /// `lights`: `DirectLights::specialization`, the kinds of light the table holds.
    /// `first_bounce_per_point`: the gather evaluates each sender's first reflection of the
    /// lights at the point it sees (`render::first_bounce_per_point`).
    /// `passes`: how the gather finishes its pixels (`fused_gather`).
    /// `bvh`: `DirectLights::bvh_specialization`, the BVH's frame and whether the gathers ask
    /// each pixel's ray for the environment, for every pipeline.
    pub fn build(
        device: &wgpu::Device,
        paging: crate::gpu::kernel::Paging,
        scene_constants: &[(&'static str, f64)],
        lights: &[(&'static str, f64)],
        bvh: &[(&'static str, f64)],
        first_bounce_per_point: bool,
        passes: GatherPasses,
    ) -> Self {
        let split = matches!(passes, GatherPasses::Split { .. });
        let sky_rays = bvh.iter().any(|&(name, value)| name == "SKY_RAYS" && value != 0.0);
        let built = SPEC.build_paged(device, paging);
        let with_scene = |constants: &[(&'static str, f64)]| [constants, scene_constants, bvh].concat();
        // Compiled for the kinds of light the table holds (the kernel's LIGHT_KINDS).
        let lights = with_scene(lights);
        let per_point = with_scene(&[("FIRST_BOUNCE_PER_POINT", first_bounce_per_point as u32 as f64)]);
        // Fused, the gather evaluates the direct light at near senders' points itself, so it
        // is compiled for the lights too.
        let gather = match passes {
            GatherPasses::Fused => [
                &[("SEEN_IN_GATHER", 1.0), ("FUSED_GATHER", 1.0)],
                lights.as_slice(),
                &[("FIRST_BOUNCE_PER_POINT", first_bounce_per_point as u32 as f64)],
            ]
            .concat(),
            GatherPasses::Split { .. } => [&[("SEEN_IN_GATHER", 1.0)], per_point.as_slice()].concat(),
        };
        // Built side by side: a CPU adapter compiles each pipeline on the thread that asks for
        // it (about 190 ms for the four on lavapipe, one after another).
        std::thread::scope(|threads| {
            let build = |entry: &'static str, constants: &[(&'static str, f64)]| {
                let built = &built;
                let constants = constants.to_vec();
                threads.spawn(move || built.specialized_pipeline(device, entry, &constants))
            };
            let direct = build("direct", &lights);
            let gather = build("gather", &gather);
            // Where each pixel's own ray finds what it receives (SKY_RAYS), the gather lists no
            // pixel for `gather_edges`: no pass over an empty list (1.1 ms a step on lavapipe).
            let edges = (split && !sky_rays).then(|| build("gather_edges", &per_point));
            // The direct light at the near senders' points, compiled like `direct`.
            let first_bounce = (split && first_bounce_per_point).then(|| build("gather_first_bounce", &lights));
            ImagePipelines {
                direct: crate::joined(direct),
                gather: crate::joined(gather),
                edges: edges.map(crate::joined),
                first_bounce: first_bounce.map(crate::joined),
                built: built.clone(),
                passes,
            }
        })
    }
}

impl ImageEstimate {
    /// `gather`: the bundle buffers of the iteration, or `None` for direct-light-only passes.
    /// `band_rows`: rows per band of the image sum (`band_rows`, or fewer to test the bands).
    /// `pixel_stride`: `iteration::pixel_stride` of the step's bundles.
    /// `pipelines`: the render's (`ImagePipelines::build`), shared by its views.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        device: &wgpu::Device,
        scene: &SceneBuffers,
        camera: &CameraItemBuffer,
        direct: &DirectLights,
        gather: Option<&GatherBuffers>,
        band_rows: u32,
        pixel_stride: u32,
        pipelines: &ImagePipelines,
    ) -> Self {
        let built = &pipelines.built;
        let split = matches!(pipelines.passes, GatherPasses::Split { .. });
        let band_rows = band_rows.max(1);
        let bands = (0..camera.height)
            .step_by(band_rows as usize)
            .map(|first_row| {
                let rows = band_rows.min(camera.height - first_row);
                let params = buffers::uniform(
                    device,
                    "firstshot.image_estimate.params",
                    &GpuEstimateParams { first_row, ..bytemuck::Zeroable::zeroed() },
                );
                let bytes = camera.width as u64 * rows as u64 * IMAGE_SUM_BYTES_PER_PIXEL;
                let sums = ["firstshot.image_estimate.direct_sum", "firstshot.image_estimate.gather_sum"]
                    .map(|label| buffers::storage_zeroed(device, label, bytes, wgpu::BufferUsages::COPY_SRC));
                // A list of at most every pixel of the band, each listed once per bundle (a
                // placeholder where the gather is fused and lists nothing).
                let list = |label| {
                    let bytes = if split { 4 * (2 * camera.width as u64 * rows as u64 + 1) } else { 16 };
                    buffers::storage_zeroed(device, label, bytes, wgpu::BufferUsages::empty())
                };
                let edges = list("firstshot.image_estimate.edges");
                let near_senders = list("firstshot.image_estimate.near_senders");
                let groups = [0, 1].map(|half| {
                    built.bind_group(
                        device,
                        0,
                        &[
                            ("camera", (&camera.camera).into()),
                            ("params", (&params).into()),
                            ("item_buffer", (&camera.ids_view).into()),
                            ("patches", scene.patches.resource()),
                            ("materials", (&scene.materials).into()),
                            ("image_sum", (&sums[half]).into()),
                            ("edges", (&edges).into()),
                            ("glossy_albedo", (&scene.glossy_albedo).into()),
                            ("near_senders", (&near_senders).into()),
                        ],
                    )
                });
                Band { first_row, rows, params, sums, edges, near_senders, groups }
            })
            .collect();
        let direct_group = built.bind_group(
            device,
            1,
            &[
                ("lights", direct.lights_buffer().into()),
                ("faces", direct.faces_buffer().into()),
                ("kept_atlas", direct.kept_atlas().into()),
                ("pass_atlas", direct.pass_atlas().into()),
                ("shadow_nodes", direct.shadow_nodes().into()),
                ("shadow_triangles", direct.shadow_triangles().into()),
                ("unshadowed", direct.unshadowed().into()),
            ],
        );
        let gather_group = Self::gather_group(device, built, gather);
        ImageEstimate {
            pipelines: pipelines.clone(),
            bands,
            direct_group,
            gather_group,
            width: camera.width,
            height: camera.height,
            pixel_stride: pixel_stride.max(1),
        }
    }

    /// Group 2; without an iteration, placeholders that `direct` never reads.
    fn gather_group(device: &wgpu::Device, built: &Kernel, gather: Option<&GatherBuffers>) -> wgpu::BindGroup {
        let placeholder;
        let (bundle, counts, slices, fragments, senders) = match gather {
            Some(g) => (&g.bundle, &g.counts, &g.slices, &g.fragments, &g.image_senders[..]),
            None => {
                let none = wgpu::BufferUsages::empty();
                let no_bundle = <GpuBundle as bytemuck::Zeroable>::zeroed();
                placeholder = [
                    buffers::storage_init(device, "firstshot.image_estimate.no_bundle", &[no_bundle], none),
                    buffers::storage_zeroed(device, "firstshot.image_estimate.no_lines", 16, none),
                    buffers::storage_zeroed(device, "firstshot.image_estimate.no_fragments", 16, none),
                    buffers::storage_zeroed(device, "firstshot.image_estimate.no_image_senders", 32, none),
                ];
                let page = std::slice::from_ref(&placeholder[3]);
                (&placeholder[0], &placeholder[1], &placeholder[1], &placeholder[2], page)
            }
        };
        built.bind_group(
            device,
            2,
            &[
                ("bundle", bundle.into()),
                ("counts", counts.into()),
                ("slices", slices.into()),
                ("fragments", fragments.into()),
                ("image_senders", crate::gpu::bindings::Resource::Pages(senders)),
            ],
        )
    }

    /// How the gather finishes its pixels (`fused_gather`).
    pub fn passes(&self) -> GatherPasses {
        self.pipelines.passes
    }

    /// Binds the bundle buffers of a new iteration (after its fragment list grew).
    pub fn rebind_gather(&mut self, device: &wgpu::Device, gather: &GatherBuffers) {
        self.gather_group = Self::gather_group(device, &self.pipelines.built, Some(gather));
    }

    /// Records one estimate of every pixel's emission and direct light, Le + D (reads the
    /// camera item buffer and the light windows of this pass).
    pub fn record_direct(&self, encoder: &mut wgpu::CommandEncoder) {
        self.record(encoder, "direct", &self.pipelines.direct, 0);
    }

    /// Records one estimate of the indirect light G of the pixels of the last bundle's class
    /// (every pixel with one bundle a step), gathered through that bundle (reads the camera
    /// item buffer of this pass): every pass of `gather_passes`, band by band.
    pub fn record_gather(&self, encoder: &mut wgpu::CommandEncoder) {
        let passes = self.passes_of_gather();
        for band in &self.bands {
            for pass in &passes {
                self.record_gather_band(encoder, band, pass);
            }
        }
    }

    /// The gather's passes, in order, as the stage profile names them: `gather` alone where
    /// it is fused; split, `gather` (which lists the pixels near their patch's edge and those
    /// with a near sender), `gather_edges` for the first list and, where senders' first
    /// bounces are evaluated per point, `gather_first_bounce` for the second.
    pub fn gather_passes(&self) -> Vec<&'static str> {
        self.passes_of_gather().iter().map(GatherPass::name).collect()
    }

    /// Records pass `pass` of `gather_passes` for every band (the stage profile times each
    /// pass alone; `record_gather` records them all, which leaves the same sums: each band's
    /// lists are its own).
    pub fn record_gather_pass(&self, encoder: &mut wgpu::CommandEncoder, pass: usize) {
        let passes = self.passes_of_gather();
        let pass =
            passes.get(pass).unwrap_or_else(|| panic!("the gather has no pass {pass} ({:?})", self.gather_passes()));
        for band in &self.bands {
            self.record_gather_band(encoder, band, pass);
        }
    }

    /// The gather's passes, from the pipelines this estimate was built with: the list passes
    /// are those it has a pipeline for (none where the gather is fused).
    fn passes_of_gather(&self) -> Vec<GatherPass<'_>> {
        let mut passes = vec![GatherPass::Main {
            edges: self.pipelines.edges.is_some(),
            near_senders: self.pipelines.first_bounce.is_some(),
        }];
        if let GatherPasses::Split { list_workgroups } = self.pipelines.passes {
            let lists = [
                ("gather_edges", "firstshot.image_estimate.gather_edges", &self.pipelines.edges),
                ("gather_first_bounce", "firstshot.image_estimate.gather_first_bounce", &self.pipelines.first_bounce),
            ];
            passes.extend(lists.into_iter().filter_map(|(name, label, pipeline)| {
                pipeline.as_ref().map(|pipeline| GatherPass::List {
                    name,
                    label,
                    pipeline,
                    workgroups: list_workgroups.max(1),
                })
            }));
        }
        passes
    }

    fn record_gather_band(&self, encoder: &mut wgpu::CommandEncoder, band: &Band, pass: &GatherPass<'_>) {
        let bind_groups = [&band.groups[1], &self.direct_group, &self.gather_group];
        match *pass {
            GatherPass::Main { edges, near_senders } => {
                if edges {
                    encoder.clear_buffer(&band.edges, 0, Some(4));
                }
                if near_senders {
                    encoder.clear_buffer(&band.near_senders, 0, Some(4));
                }
                // One invocation per block of stride x stride pixels that meets the band's rows.
                let stride = self.pixel_stride;
                let block_rows = (band.first_row + band.rows).div_ceil(stride) - band.first_row / stride;
                let groups = SPEC.grid("gather", [self.width.div_ceil(stride), block_rows]);
                kernel::dispatch(
                    encoder,
                    "firstshot.image_estimate.gather",
                    &self.pipelines.gather,
                    &bind_groups,
                    groups,
                );
            }
            GatherPass::List { label, pipeline, workgroups, .. } => {
                kernel::dispatch(encoder, label, pipeline, &bind_groups, (workgroups, 1));
            }
        }
    }

    fn record(&self, encoder: &mut wgpu::CommandEncoder, entry: &str, pipeline: &wgpu::ComputePipeline, half: usize) {
        for band in &self.bands {
            let groups = SPEC.grid(entry, [self.width, band.rows]);
            let bind_groups = [&band.groups[half], &self.direct_group, &self.gather_group];
            kernel::dispatch(encoder, "firstshot.image_estimate.pass", pipeline, &bind_groups, groups);
        }
    }

    /// The buffers of the image sum in the order of `read_sum`: the first half's bands from
    /// the top, then the second half's (checkpoints keep and restore them in this order).
    pub fn sum_buffers(&self) -> impl Iterator<Item = &wgpu::Buffer> {
        (0..2).flat_map(move |half| self.bands.iter().map(move |b| &b.sums[half]))
    }

    /// What the estimate adds where no surface is, how many direct lights it evaluates,
    /// whether the emitting shapes' direct light is shared between D and G (`mis`,
    /// docs/ALGORITHM.md 6: only where the image gathers and the scene has first-shot emitting
    /// shapes; a direct-light image must not share it), and whether the image gathers
    /// (`gathers`: then G's half, every step, holds the emission Le each pixel sees, and D's
    /// half D and the environment; a direct-light image keeps Le with D).
    pub fn set_params(
        &self,
        queue: &wgpu::Queue,
        environment: [f32; 3],
        patch_count: u32,
        light_count: u32,
        mis: bool,
        gathers: bool,
    ) {
        for band in &self.bands {
            let params = GpuEstimateParams {
                environment: [environment[0], environment[1], environment[2], 0.0],
                patch_count,
                light_count,
                mis: mis as u32,
                first_row: band.first_row,
                seen_in_gather: gathers as u32,
                _pad: [0; 3],
            };
            queue.write_buffer(&band.params, 0, bytemuck::bytes_of(&params));
        }
    }

    /// Clears the running sum.
    pub fn clear(&self, encoder: &mut wgpu::CommandEncoder) {
        for sum in self.sum_buffers() {
            encoder.clear_buffer(sum, 0, None);
        }
    }

    /// Reads the image sum back (its two halves, Le + D then G, of rgb sum and w the number
    /// of estimates per pixel, each row by row from the top).
    pub fn read_sum(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Vec<[f32; 4]>> {
        let mut sum = Vec::with_capacity(2 * self.width as usize * self.height as usize);
        let band_bytes = |band: &Band| self.width as u64 * band.rows as u64 * IMAGE_SUM_BYTES_PER_PIXEL;
        let staging = buffers::staging_buffer(device, self.bands.iter().map(band_bytes).max().unwrap_or(0));
        for (buffer, band) in self.sum_buffers().zip(self.bands.iter().chain(&self.bands)) {
            buffers::read_back_via(device, queue, buffer, 0, band_bytes(band), &staging, &mut sum)?;
        }
        Ok(sum)
    }

    /// Reads the image back, row by row from the top (`image_of_sums`).
    pub fn read_mean(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Vec<[f32; 3]>> {
        image_of_sums(&self.read_sum(device, queue)?)
    }
}

/// The image of an image sum (two halves of rgb sum, w count per pixel: Le + D, then G): per
/// pixel the mean of the first half plus the mean of the second (zero where no step has
/// gathered yet, as in a direct-light image), each mean and their sum in f32 (`merge`
/// reproduces it bit for bit from a part).
pub fn image_of_sums(sums: &[[f32; 4]]) -> Result<Vec<[f32; 3]>> {
    let (direct, gathered) = sums.split_at(sums.len() / 2);
    let mean = |s: &[f32; 4]| [s[0] / s[3], s[1] / s[3], s[2] / s[3]];
    direct
        .iter()
        .zip(gathered)
        .map(|(d, g)| {
            if d[3] <= 0.0 || d[3].is_nan() {
                return Err(Error::Gpu("the image holds no estimate of the direct light".into()));
            }
            let (d, g) = (mean(d), if g[3] > 0.0 { mean(g) } else { [0.0; 3] });
            Ok([d[0] + g[0], d[1] + g[1], d[2] + g[2]])
        })
        .collect()
}
