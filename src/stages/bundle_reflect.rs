//! Bundle reflection (`wgsl/bundle_reflect.wgsl`): O_j of every patch into this step's
//! bundle, and the step's largest radiance.

use crate::gpu::bindings::{Kernel, KernelSpec, compute, read, read_write};
use crate::gpu::kernel;
use crate::gpu::scene_buffers::{
    FIRST_SHOT_TABLE_GROUP, IMAGE_SENDERS, OUTGOING, PATCH_STATE, PATCH_TABLE, Paged, SceneBuffers,
};
use crate::layout::{GpuBundle, GpuImageSender, GpuMaterial, GpuPatch, GpuPatchState};

pub const SPEC: KernelSpec = KernelSpec {
    stem: "bundle_reflect",
    visibility: wgpu::ShaderStages::COMPUTE,
    // One invocation per patch.
    entry_points: &[compute("main", [64, 1, 1])],
    groups: &[
        &[
            // The step's bundle, as a storage buffer, not a uniform: lavapipe builds uniform
            // values that steer a kernel's code into variants of it, compiled at dispatch, and
            // with the glossy history's ten terms this kernel was compiled again at every step
            // of a seed not seen before (docs/PERFORMANCE.md, "A longer glossy history").
            read::<GpuBundle>("bundle"),
            read::<GpuPatch>("patches").paged(PATCH_TABLE.pages),
            read::<GpuMaterial>("materials"),
            // J_j, win_j of the previous step.
            read::<GpuPatchState>("state").paged(PATCH_STATE.pages),
            // rgb O_j, w s_j; one writer per patch.
            read_write::<[f32; 4]>("outgoing").paged(OUTGOING.pages),
            // Bits of the largest O channel (positive floats order like their bits).
            read_write::<u32>("max_bits"),
            // What the image gathers from j and Lbar_j as this step found it
            // (`GpuImageSender`; with `writes_first_bounce` Lfs_j in their w slots,
            // `pack_first_bounce` in wgsl/bundle_reflect.wgsl); one writer per patch.
            read_write::<GpuImageSender>("image_senders").paged(IMAGE_SENDERS.pages),
        ],
        FIRST_SHOT_TABLE_GROUP,
    ],
};

pub struct BundleReflect {
    kernel: Kernel,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    table_group: wgpu::BindGroup,
    patch_count: u32,
}

/// What a reflection writes for each patch: O_j into the bundle, and what the image's
/// gather reads (`SPEC`'s bindings of the same names).
pub struct ReflectOutputs<'a> {
    pub outgoing: &'a Paged,
    pub image_senders: &'a Paged,
    /// Whether the image evaluates near senders' first bounce per point and so reads Lfs_j,
    /// which then rides in the w slots of `image_senders`.
    pub writes_first_bounce: bool,
}

impl BundleReflect {
    /// `like`: a stage over arrays of the same paging whose pipeline this one shares (and
    /// its `writes_first_bounce`).
    pub fn new(
        device: &wgpu::Device,
        scene: &SceneBuffers,
        bundle: &wgpu::Buffer,
        max_bits: &wgpu::Buffer,
        outputs: ReflectOutputs<'_>,
        like: Option<&Self>,
    ) -> Self {
        let ReflectOutputs { outgoing, image_senders, writes_first_bounce } = outputs;
        let (built, pipeline) = match like {
            Some(like) => (like.kernel.clone(), like.pipeline.clone()),
            None => {
                let built = SPEC.build_paged(device, scene.paging());
                // Not compiled without the glossy code (`SceneBuffers::constants`): built so,
                // lavapipe recompiled this kernel at nearly every step, apparently specialising
                // it on values of the step's uniform (docs/PERFORMANCE.md, "Uniform inlining on
                // lavapipe").
                let constants = [("IMAGE_FIRST_BOUNCE", writes_first_bounce as u32 as f64)];
                let pipeline = built.specialized_pipeline(device, "main", &constants);
                (built, pipeline)
            }
        };
        BundleReflect {
            pipeline,
            bind_group: built.bind_group(
                device,
                0,
                &[
                    ("bundle", bundle.into()),
                    ("patches", scene.patches.resource()),
                    ("materials", (&scene.materials).into()),
                    ("state", scene.state.resource()),
                    ("outgoing", outgoing.resource()),
                    ("max_bits", max_bits.into()),
                    ("image_senders", image_senders.resource()),
                ],
            ),
            table_group: scene.first_shot.bind_group(device, &built.layouts[1], built.paging, &scene.samples),
            patch_count: scene.patch_count,
            kernel: built,
        }
    }

    pub fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let groups = SPEC.linear("main", self.patch_count);
        let bind_groups = [&self.bind_group, &self.table_group];
        kernel::dispatch(encoder, "firstshot.bundle_reflect.pass", &self.pipeline, &bind_groups, groups);
    }
}
