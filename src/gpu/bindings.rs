//! What each kernel binds, declared once: a `KernelSpec` per stage (its entry points with
//! their workgroup sizes, and its bind groups as lists of named bindings). The host builds
//! every bind-group layout, pipeline layout, bind group and dispatch count from it, and
//! `check` holds a spec against naga's reflection of `wgsl/<stem>.wgsl`, so that a binding or
//! workgroup size that differs between WGSL and Rust fails `cargo test`, not a render.
//!
//! Binding `i` of a group is entry `i` of its list; its name is the WGSL variable's.

use super::kernel;
use std::num::NonZeroU64;

/// The type of one binding, as the host declares it in the layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BindKind {
    /// `var<uniform>` of at least `min_size` bytes.
    Uniform { min_size: u64 },
    /// `var<storage, read>` (`read_only`) or `var<storage, read_write>`; `min_size` bytes at
    /// least (one element of a runtime-sized array).
    Storage { read_only: bool, min_size: u64 },
    /// `texture_2d<u32>`, read with `textureLoad` (item buffers).
    UintTexture2d,
}

/// One binding: the WGSL variable's name and its kind.
///
/// A paged storage binding (`pages` > 1) is an array split over that many buffers, none
/// larger than one binding allows: page 0 is the variable `name` at this binding, pages 1 and
/// on the variables `name_1`, `name_2`, ... at bindings after every entry of the group's list
/// (`entries`); `gpu::kernel::source` declares them and the accessors that select the page
/// (`name_at(i)`, `name_set(i, v)`, `name_add(i, v)` for atomics) from the length of page 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Binding {
    pub name: &'static str,
    pub kind: BindKind,
    pub pages: u32,
}

impl Binding {
    /// This storage binding split over `pages` buffers (see `Binding`).
    pub const fn paged(self, pages: u32) -> Binding {
        assert!(matches!(self.kind, BindKind::Storage { .. }) && pages >= 1);
        Binding { pages, ..self }
    }
}

/// One entry of a bind group's layout: `binding` number, variable name, kind, and the page
/// (0 for an unpaged binding) of spec binding `index`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Entry {
    pub binding: u32,
    pub name: String,
    pub kind: BindKind,
    pub index: usize,
    pub page: u32,
}

/// The layout entries of a group's `bindings`: binding i at i, then the pages after the first
/// of each paged binding, in order; with `Paging::Whole` none of those (the kernel indexes
/// page 0 alone, and lavapipe slows every dispatch down by a multiple for bindings a shader
/// leaves unused: tests/iteration.rs test02 took 8.6 s with them, 3.3 s without).
pub fn entries(bindings: &[Binding], paging: kernel::Paging) -> Vec<Entry> {
    let mut out: Vec<Entry> = bindings
        .iter()
        .enumerate()
        .map(|(i, b)| Entry { binding: i as u32, name: b.name.to_string(), kind: b.kind, index: i, page: 0 })
        .collect();
    for (i, b) in bindings.iter().enumerate().filter(|_| paging == kernel::Paging::Paged) {
        for page in 1..b.pages {
            let binding = out.len() as u32;
            out.push(Entry { binding, name: format!("{}_{page}", b.name), kind: b.kind, index: i, page });
        }
    }
    out
}

/// Storage buffers a kernel binds, which a device limits per stage: with `Paging::Paged` every
/// page of a paged array counts, with `Paging::Whole` (every array in one page) only the first
/// is bound (`entries`).
pub fn storage_buffers(spec: &KernelSpec, paging: kernel::Paging) -> u32 {
    spec.groups
        .iter()
        .flat_map(|g| g.iter())
        .filter(|b| matches!(b.kind, BindKind::Storage { .. }))
        .map(|b| if paging == kernel::Paging::Paged { b.pages } else { 1 })
        .sum()
}

/// How a kernel binding `resources` reaches its paged arrays: `Paging::Paged` if any of them
/// has more than one page.
pub fn paging(resources: &[Resource]) -> kernel::Paging {
    let paged = resources.iter().any(|r| matches!(r, Resource::Pages(p) if p.len() > 1));
    if paged { kernel::Paging::Paged } else { kernel::Paging::Whole }
}

/// A uniform holding one `T`.
pub const fn uniform<T>(name: &'static str) -> Binding {
    Binding { name, kind: BindKind::Uniform { min_size: std::mem::size_of::<T>() as u64 }, pages: 1 }
}

/// A read-only storage buffer of `T`s (or one `T`).
pub const fn read<T>(name: &'static str) -> Binding {
    Binding { name, kind: BindKind::Storage { read_only: true, min_size: std::mem::size_of::<T>() as u64 }, pages: 1 }
}

/// A writable storage buffer of `T`s (or one `T`).
pub const fn read_write<T>(name: &'static str) -> Binding {
    Binding { name, kind: BindKind::Storage { read_only: false, min_size: std::mem::size_of::<T>() as u64 }, pages: 1 }
}

/// A `texture_2d<u32>`.
pub const fn uint_texture(name: &'static str) -> Binding {
    Binding { name, kind: BindKind::UintTexture2d, pages: 1 }
}

/// The shader stage of an entry point; compute ones carry their workgroup size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    Compute { workgroup_size: [u32; 3] },
    Vertex,
    Fragment,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EntryPoint {
    pub name: &'static str,
    pub stage: Stage,
}

pub const fn compute(name: &'static str, workgroup_size: [u32; 3]) -> EntryPoint {
    EntryPoint { name, stage: Stage::Compute { workgroup_size } }
}

pub const fn vertex(name: &'static str) -> EntryPoint {
    EntryPoint { name, stage: Stage::Vertex }
}

pub const fn fragment(name: &'static str) -> EntryPoint {
    EntryPoint { name, stage: Stage::Fragment }
}

/// A kernel's interface: `wgsl/<stem>.wgsl`, its entry points, and its bind groups (group
/// `g` is `groups[g]`). `visibility`: the stages that see its bindings; writable storage is
/// never visible to vertex shaders (an optional feature the portable path does without).
#[derive(Debug, Clone, Copy)]
pub struct KernelSpec {
    pub stem: &'static str,
    pub visibility: wgpu::ShaderStages,
    pub entry_points: &'static [EntryPoint],
    pub groups: &'static [&'static [Binding]],
}

/// The stages that see `kind` in a kernel whose bindings are visible to `visibility`.
pub fn binding_visibility(kind: BindKind, visibility: wgpu::ShaderStages) -> wgpu::ShaderStages {
    match kind {
        BindKind::Storage { read_only: false, .. } => visibility - wgpu::ShaderStages::VERTEX,
        _ => visibility,
    }
}

/// The bind-group layout of `bindings` (`entries`).
pub fn group_layout(
    device: &wgpu::Device,
    label: &str,
    visibility: wgpu::ShaderStages,
    bindings: &[Binding],
    paging: kernel::Paging,
) -> wgpu::BindGroupLayout {
    let entries: Vec<wgpu::BindGroupLayoutEntry> = entries(bindings, paging)
        .into_iter()
        .map(|b| wgpu::BindGroupLayoutEntry {
            binding: b.binding,
            visibility: binding_visibility(b.kind, visibility),
            ty: match b.kind {
                BindKind::Uniform { min_size } => wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: NonZeroU64::new(min_size),
                },
                BindKind::Storage { read_only, min_size } => wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: NonZeroU64::new(min_size),
                },
                BindKind::UintTexture2d => wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Uint,
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
            },
            count: None,
        })
        .collect();
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries })
}

/// What one binding of a bind group is bound to.
#[derive(Debug, Clone, Copy)]
pub enum Resource<'a> {
    /// The whole buffer.
    Buffer(&'a wgpu::Buffer),
    /// The first `size` bytes of the buffer.
    BufferPrefix(&'a wgpu::Buffer, NonZeroU64),
    /// The pages of a paged binding, as many as it has at most (`Binding::pages`); a page
    /// past the last is bound to the first (never read).
    Pages(&'a [wgpu::Buffer]),
    Texture(&'a wgpu::TextureView),
}

impl<'a> From<&'a wgpu::Buffer> for Resource<'a> {
    fn from(buffer: &'a wgpu::Buffer) -> Self {
        Resource::Buffer(buffer)
    }
}

impl<'a> From<&'a wgpu::TextureView> for Resource<'a> {
    fn from(view: &'a wgpu::TextureView) -> Self {
        Resource::Texture(view)
    }
}

/// A bind group over `layout` (built from `bindings` with `paging`) with `resources` named as
/// the bindings are, in order. A name, count or kind that differs is a programming error: it
/// panics, as does an array of several pages given to a kernel that indexes page 0 alone.
pub fn bind_group(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    bindings: &[Binding],
    paging: kernel::Paging,
    resources: &[(&str, Resource)],
) -> wgpu::BindGroup {
    let names = || bindings.iter().map(|b| b.name).collect::<Vec<_>>();
    assert!(
        bindings.len() == resources.len(),
        "{label}: {} resources for the {} bindings {:?}",
        resources.len(),
        bindings.len(),
        names()
    );
    let entries: Vec<wgpu::BindGroupEntry> = entries(bindings, paging)
        .into_iter()
        .map(|e| {
            let (i, b, (name, resource)) = (e.index, &bindings[e.index], &resources[e.index]);
            assert!(b.name == *name, "{label}: binding {i} is `{}` in the spec, `{name}` here", b.name);
            let resource = match (b.kind, *resource) {
                (BindKind::Storage { .. }, Resource::Pages(pages)) => {
                    assert!(
                        !pages.is_empty() && pages.len() as u32 <= b.pages,
                        "{label}: {} pages for `{name}`, which has {}",
                        pages.len(),
                        b.pages
                    );
                    assert!(
                        paging == kernel::Paging::Paged || pages.len() == 1,
                        "{label}: {} pages for `{name}`, bound to a kernel built for one (Paging::Whole)",
                        pages.len()
                    );
                    pages.get(e.page as usize).unwrap_or(&pages[0]).as_entire_binding()
                }
                (_, Resource::Pages(_)) => panic!("{label}: binding {i} `{name}` is not a storage buffer"),
                (BindKind::Storage { .. }, _) if b.pages > 1 => {
                    panic!("{label}: binding {i} `{name}` is paged; give it Resource::Pages")
                }
                (BindKind::UintTexture2d, Resource::Texture(view)) => wgpu::BindingResource::TextureView(view),
                (BindKind::Uniform { .. } | BindKind::Storage { .. }, Resource::Buffer(buffer)) => {
                    buffer.as_entire_binding()
                }
                (BindKind::Uniform { .. } | BindKind::Storage { .. }, Resource::BufferPrefix(buffer, size)) => {
                    wgpu::BindingResource::Buffer(wgpu::BufferBinding { buffer, offset: 0, size: Some(size) })
                }
                (kind, _) => panic!("{label}: binding {i} `{name}` is {kind:?}, not what was given"),
            };
            wgpu::BindGroupEntry { binding: e.binding, resource }
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
}

impl KernelSpec {
    /// The entry point `name`; a name the spec lacks is a programming error.
    pub fn entry_point(&self, name: &str) -> &EntryPoint {
        self.entry_points
            .iter()
            .find(|e| e.name == name)
            .unwrap_or_else(|| panic!("{}: no entry point `{name}` in its KernelSpec", self.stem))
    }

    /// The declared workgroup size of compute entry point `name`.
    pub fn workgroup_size(&self, name: &str) -> [u32; 3] {
        match self.entry_point(name).stage {
            Stage::Compute { workgroup_size } => workgroup_size,
            stage => panic!("{}: `{name}` is a {stage:?} entry point, not a compute one", self.stem),
        }
    }

    /// Workgroups covering a `size[0]` x `size[1]` grid of invocations.
    pub fn grid(&self, entry: &str, size: [u32; 2]) -> (u32, u32) {
        let [x, y, _] = self.workgroup_size(entry);
        (size[0].div_ceil(x), size[1].div_ceil(y))
    }

    /// Workgroups covering `n` invocations of a one-dimensional entry point (at least one),
    /// folded into 2D past the 65535 limit: the kernel indexes `gid.x + gid.y * groups.x * w`.
    pub fn linear(&self, entry: &str, n: u32) -> (u32, u32) {
        let [x, y, z] = self.workgroup_size(entry);
        assert!(y == 1 && z == 1, "{}: `{entry}` is not one-dimensional", self.stem);
        fold_2d(n.div_ceil(x))
    }

    /// The shader module of `wgsl/<stem>.wgsl`, its paged arrays reached as `paging` says.
    pub fn module(&self, device: &wgpu::Device, paging: kernel::Paging) -> wgpu::ShaderModule {
        kernel::module(device, self.stem, paging)
    }

    /// Whether any binding is paged (`Binding::paged`).
    pub fn has_paged_bindings(&self) -> bool {
        self.groups.iter().flat_map(|g| g.iter()).any(|b| b.pages > 1)
    }

    /// One bind-group layout per group, labelled `firstshot.<stem>.layout` (group 0) and
    /// `firstshot.<stem>.group<g>.layout`.
    pub fn layouts(&self, device: &wgpu::Device, paging: kernel::Paging) -> Vec<wgpu::BindGroupLayout> {
        (0..self.groups.len())
            .map(|g| group_layout(device, &self.label(g, "layout"), self.visibility, self.groups[g], paging))
            .collect()
    }

    /// The pipeline layout over `layouts` (from `layouts`).
    pub fn pipeline_layout(&self, device: &wgpu::Device, layouts: &[wgpu::BindGroupLayout]) -> wgpu::PipelineLayout {
        assert_eq!(layouts.len(), self.groups.len(), "{}: one layout per bind group", self.stem);
        let layouts: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().map(Some).collect();
        device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(&format!("firstshot.{}.pipeline_layout", self.stem)),
            bind_group_layouts: &layouts,
            immediate_size: 0,
        })
    }

    /// The module, the bind-group layouts and the pipeline layout, which every stage builds
    /// first; for a kernel without paged bindings (else `build_paged`).
    pub fn build(&self, device: &wgpu::Device) -> Kernel {
        assert!(!self.has_paged_bindings(), "{}: has paged bindings; build it with build_paged", self.stem);
        self.build_paged(device, kernel::Paging::Whole)
    }

    /// As `build`, the paged arrays reached as `paging` says: `Paging::Whole` only when every
    /// array bound to a paged binding has one page in this run.
    pub fn build_paged(&self, device: &wgpu::Device, paging: kernel::Paging) -> Kernel {
        let layouts = self.layouts(device, paging);
        Kernel {
            spec: *self,
            module: self.module(device, paging),
            pipeline_layout: self.pipeline_layout(device, &layouts),
            layouts,
            paging,
        }
    }

    /// The compute pipeline of entry point `entry`, labelled `firstshot.<stem>.<entry>`, with
    /// the kernel's `override` constants set as `constants` says (the rest at their defaults).
    pub fn compute_pipeline(
        &self,
        device: &wgpu::Device,
        module: &wgpu::ShaderModule,
        layout: &wgpu::PipelineLayout,
        entry: &str,
        constants: &[(&str, f64)],
    ) -> wgpu::ComputePipeline {
        self.workgroup_size(entry);
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(&format!("firstshot.{}.{entry}", self.stem)),
            layout: Some(layout),
            module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
            cache: None,
        })
    }

    /// Bind group `group` over its layout (made with `paging`), `resources` named as the
    /// spec's bindings.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        group: usize,
        layout: &wgpu::BindGroupLayout,
        paging: kernel::Paging,
        resources: &[(&str, Resource)],
    ) -> wgpu::BindGroup {
        bind_group(device, &self.label(group, "bind_group"), layout, self.groups[group], paging, resources)
    }

    /// As `bind_group`, for a group of buffers given in binding order (whole buffers).
    pub fn buffer_bind_group(
        &self,
        device: &wgpu::Device,
        group: usize,
        layout: &wgpu::BindGroupLayout,
        paging: kernel::Paging,
        buffers: &[&wgpu::Buffer],
    ) -> wgpu::BindGroup {
        let bindings = self.groups[group];
        assert!(
            bindings.len() == buffers.len(),
            "{}: {} buffers for the {} bindings of group {group}",
            self.stem,
            buffers.len(),
            bindings.len()
        );
        let named: Vec<(&str, Resource)> =
            bindings.iter().zip(buffers).map(|(b, buf)| (b.name, (*buf).into())).collect();
        self.bind_group(device, group, layout, paging, &named)
    }

    fn label(&self, group: usize, what: &str) -> String {
        match group {
            0 => format!("firstshot.{}.{what}", self.stem),
            g => format!("firstshot.{}.group{g}.{what}", self.stem),
        }
    }
}

/// A kernel built from its spec: what its pipelines and bind groups are made from.
#[derive(Clone)]
pub struct Kernel {
    pub spec: KernelSpec,
    pub module: wgpu::ShaderModule,
    /// One per bind group.
    pub layouts: Vec<wgpu::BindGroupLayout>,
    pub pipeline_layout: wgpu::PipelineLayout,
    /// How its WGSL reaches the paged arrays, and so which page bindings its layouts have.
    pub paging: kernel::Paging,
}

impl Kernel {
    /// The compute pipeline of entry point `entry`.
    pub fn compute_pipeline(&self, device: &wgpu::Device, entry: &str) -> wgpu::ComputePipeline {
        self.spec.compute_pipeline(device, &self.module, &self.pipeline_layout, entry, &[])
    }

    /// As `compute_pipeline`, specialised: the kernel's `override` constants named in
    /// `constants` take those values.
    pub fn specialized_pipeline(
        &self,
        device: &wgpu::Device,
        entry: &str,
        constants: &[(&str, f64)],
    ) -> wgpu::ComputePipeline {
        self.spec.compute_pipeline(device, &self.module, &self.pipeline_layout, entry, constants)
    }

    /// Bind group `group`, `resources` named as the spec's bindings, in order.
    pub fn bind_group(&self, device: &wgpu::Device, group: usize, resources: &[(&str, Resource)]) -> wgpu::BindGroup {
        self.spec.bind_group(device, group, &self.layouts[group], self.paging, resources)
    }

    /// Bind group `group` of whole buffers, in binding order.
    pub fn buffer_bind_group(&self, device: &wgpu::Device, group: usize, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        self.spec.buffer_bind_group(device, group, &self.layouts[group], self.paging, buffers)
    }

    /// Bind group `group` of `resources` in binding order (whole buffers or pages).
    pub fn resource_bind_group(&self, device: &wgpu::Device, group: usize, resources: &[Resource]) -> wgpu::BindGroup {
        let bindings = self.spec.groups[group];
        assert!(
            bindings.len() == resources.len(),
            "{}: {} resources for group {group}",
            self.spec.stem,
            resources.len()
        );
        let named: Vec<(&str, Resource)> = bindings.iter().zip(resources).map(|(b, r)| (b.name, *r)).collect();
        self.bind_group(device, group, &named)
    }
}

/// Workgroup counts for `blocks` workgroups (at least one), folded into 2D past the 65535
/// limit of one dimension.
pub fn fold_2d(blocks: u32) -> (u32, u32) {
    const MAX: u32 = 65535;
    if blocks <= MAX { (blocks.max(1), 1) } else { (MAX, blocks.div_ceil(MAX)) }
}

/// Every difference between `spec` and naga's reflection of its WGSL (`module`, validated
/// into `info`): bindings missing on either side, names, kinds, access and sizes, entry
/// points and their workgroup sizes, and globals an entry point uses that its stage cannot
/// see. Empty when they agree.
pub fn check(spec: &KernelSpec, module: &naga::Module, info: &naga::valid::ModuleInfo) -> Vec<String> {
    let mut errors = Vec::new();
    let stem = spec.stem;
    let groups: Vec<Vec<Entry>> = spec.groups.iter().map(|g| entries(g, kernel::Paging::Paged)).collect();
    let declared = |group: u32, binding: u32| groups.get(group as usize)?.get(binding as usize);
    for (_, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        let name = var.name.as_deref().unwrap_or("?");
        let at = format!("{stem}: @group({}) @binding({}) `{name}`", rb.group, rb.binding);
        let Some(b) = declared(rb.group, rb.binding) else {
            errors.push(format!("{at} is in the WGSL but not in the spec"));
            continue;
        };
        if b.name != name {
            errors.push(format!("{at} is named `{}` in the spec", b.name));
        }
        if let Some(e) = kind_mismatch(b.kind, var, module) {
            errors.push(format!("{at}: {e}"));
        }
    }
    for (g, group) in groups.iter().enumerate() {
        for (i, b) in group.iter().enumerate() {
            let found = module
                .global_variables
                .iter()
                .any(|(_, v)| v.binding.as_ref().is_some_and(|rb| rb.group as usize == g && rb.binding as usize == i));
            if !found {
                errors.push(format!("{stem}: the spec binds group {g} binding {i} `{}`, the WGSL does not", b.name));
            }
        }
    }
    check_entry_points(spec, module, info, &mut errors);
    errors
}

fn kind_mismatch(kind: BindKind, var: &naga::GlobalVariable, module: &naga::Module) -> Option<String> {
    let inner = &module.types[var.ty].inner;
    let size = || inner.size(module.to_ctx()) as u64;
    match (kind, var.space) {
        (BindKind::Uniform { min_size }, naga::AddressSpace::Uniform) => {
            (min_size < size()).then(|| format!("min size {min_size} in the spec, the WGSL type needs {}", size()))
        }
        (BindKind::Storage { read_only, min_size }, naga::AddressSpace::Storage { access }) => {
            let wgsl_read_only = !access.contains(naga::StorageAccess::STORE);
            if read_only != wgsl_read_only {
                let access = |r: bool| if r { "read" } else { "read_write" };
                Some(format!("{} in the spec, {} in the WGSL", access(read_only), access(wgsl_read_only)))
            } else if min_size < size() {
                Some(format!("min size {min_size} in the spec, the WGSL type needs {}", size()))
            } else {
                None
            }
        }
        (BindKind::UintTexture2d, naga::AddressSpace::Handle) => match inner {
            naga::TypeInner::Image {
                dim: naga::ImageDimension::D2,
                arrayed: false,
                class: naga::ImageClass::Sampled { kind: naga::ScalarKind::Uint, multi: false },
            } => None,
            other => Some(format!("a texture_2d<u32> in the spec, {other:?} in the WGSL")),
        },
        (kind, space) => Some(format!("{kind:?} in the spec, address space {space:?} in the WGSL")),
    }
}

fn check_entry_points(
    spec: &KernelSpec,
    module: &naga::Module,
    info: &naga::valid::ModuleInfo,
    errors: &mut Vec<String>,
) {
    let stem = spec.stem;
    for declared in spec.entry_points {
        if !module.entry_points.iter().any(|e| e.name == declared.name) {
            errors.push(format!("{stem}: the spec's entry point `{}` is not in the WGSL", declared.name));
        }
    }
    for (index, ep) in module.entry_points.iter().enumerate() {
        let Some(declared) = spec.entry_points.iter().find(|e| e.name == ep.name) else {
            errors.push(format!("{stem}: entry point `{}` is in the WGSL but not in the spec", ep.name));
            continue;
        };
        let (stage, wgsl_stage) = match (declared.stage, ep.stage) {
            (Stage::Compute { workgroup_size }, naga::ShaderStage::Compute) => {
                if ep.workgroup_size_overrides.is_some() {
                    errors.push(format!("{stem}: `{}` has an overridable workgroup size", ep.name));
                } else if workgroup_size != ep.workgroup_size {
                    errors.push(format!(
                        "{stem}: `{}` has workgroup size {workgroup_size:?} in the spec, {:?} in the WGSL",
                        ep.name, ep.workgroup_size
                    ));
                }
                (wgpu::ShaderStages::COMPUTE, ep.stage)
            }
            (Stage::Vertex, naga::ShaderStage::Vertex) => (wgpu::ShaderStages::VERTEX, ep.stage),
            (Stage::Fragment, naga::ShaderStage::Fragment) => (wgpu::ShaderStages::FRAGMENT, ep.stage),
            (stage, wgsl_stage) => {
                errors.push(format!("{stem}: `{}` is {stage:?} in the spec, {wgsl_stage:?} in the WGSL", ep.name));
                continue;
            }
        };
        let uses = info.get_entry_point(index);
        for (handle, var) in module.global_variables.iter() {
            let Some(rb) = &var.binding else { continue };
            let Some(b) = spec
                .groups
                .get(rb.group as usize)
                .and_then(|g| entries(g, kernel::Paging::Paged).into_iter().nth(rb.binding as usize))
            else {
                continue;
            };
            if !uses[handle].is_empty() && !binding_visibility(b.kind, spec.visibility).contains(stage) {
                errors.push(format!(
                    "{stem}: {wgsl_stage:?} entry point `{}` uses `{}`, which the spec's visibility hides from it",
                    ep.name, b.name
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::bundle_finalize;

    /// `bindings::check` of a spec built from `bundle_finalize::SPEC` by `edit`.
    fn errors_of(edit: impl FnOnce(&mut KernelSpec, &mut Vec<Binding>, &mut Vec<EntryPoint>)) -> Vec<String> {
        let mut spec = bundle_finalize::SPEC;
        let mut group = spec.groups[0].to_vec();
        let mut entries = spec.entry_points.to_vec();
        edit(&mut spec, &mut group, &mut entries);
        let group: &'static [Binding] = group.leak();
        spec.groups = Vec::leak(vec![group]);
        spec.entry_points = entries.leak();
        let (module, info) = kernel::reflect(spec.stem).unwrap();
        check(&spec, &module, &info)
    }

    fn assert_reported(errors: &[String], needle: &str) {
        assert!(errors.iter().any(|e| e.contains(needle)), "expected an error with `{needle}`, got {errors:#?}");
    }

    #[test]
    fn the_unchanged_spec_passes() {
        assert_eq!(errors_of(|_, _, _| {}), Vec::<String>::new());
    }

    #[test]
    fn a_wrong_access_is_reported() {
        let errors = errors_of(|_, g, _| g[2] = read::<u32>("sums"));
        assert_reported(&errors, "`sums`: read in the spec, read_write in the WGSL");
    }

    #[test]
    fn a_wrong_kind_or_name_is_reported() {
        let errors = errors_of(|_, g, _| {
            g[0] = read::<crate::layout::GpuBundle>("bundle");
            g[1].name = "patch";
        });
        assert_reported(&errors, "`bundle`: Storage");
        assert_reported(&errors, "is named `patch` in the spec");
    }

    #[test]
    fn a_too_small_binding_is_reported() {
        let errors = errors_of(|_, g, _| g[5] = read_write::<[f32; 4]>("state"));
        assert_reported(&errors, "`state`: min size 16 in the spec");
    }

    #[test]
    fn missing_and_extra_bindings_are_reported() {
        // The pages of paged bindings follow the whole list: without the last binding
        // (`materials`) every page moves down one, and `state`'s last page (binding 25 of the
        // WGSL) is beyond the spec; with one more binding, the spec's last page moves past
        // the WGSL's.
        assert_reported(&errors_of(|_, g, _| _ = g.pop()), "`state_10` is in the WGSL but not in the spec");
        assert_reported(&errors_of(|_, g, _| g.push(read::<u32>("extra"))), "binding 26 `state_10`, the WGSL does not");
        assert_reported(&errors_of(|_, g, _| g[5] = g[5].paged(2)), "`state_2` is in the WGSL but not in the spec");
    }

    #[test]
    fn a_wrong_workgroup_size_or_entry_point_is_reported() {
        let errors = errors_of(|_, _, e| e[0] = compute("main", [32, 1, 1]));
        assert_reported(&errors, "workgroup size [32, 1, 1] in the spec, [64, 1, 1] in the WGSL");
        let errors = errors_of(|_, _, e| e[0] = compute("run", [64, 1, 1]));
        assert_reported(&errors, "entry point `run` is not in the WGSL");
        assert_reported(&errors, "entry point `main` is in the WGSL but not in the spec");
        assert_reported(&errors_of(|_, _, e| e[0] = fragment("main")), "is Fragment in the spec, Compute");
    }

    #[test]
    fn a_binding_hidden_from_its_stage_is_reported() {
        let errors = errors_of(|s, _, _| s.visibility = wgpu::ShaderStages::FRAGMENT);
        assert_reported(&errors, "uses `bundle`, which the spec's visibility hides from it");
    }

    #[test]
    fn dispatch_counts_come_from_the_workgroup_size() {
        let spec = crate::stages::first_shot_reduce::SPEC;
        assert_eq!(spec.grid("reduce_face", [17, 8]), (3, 1));
        assert_eq!(spec.linear("append_sample", 0), (1, 1));
        assert_eq!(spec.linear("append_sample", 65), (2, 1));
        assert_eq!(spec.linear("append_sample", 64 * 65536), (65535, 2));
    }
}
