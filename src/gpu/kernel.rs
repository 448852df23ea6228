//! WGSL sources: every kernel is one file in `wgsl/`, compiled with the generated constant
//! header and the shared files of `wgsl/common/` in front of it.

use crate::gpu::scene_buffers::FIRST_SHOT_TABLE_GROUP;
use crate::layout;

/// Shared WGSL, prepended to every kernel in this order.
const COMMON: &[(&str, &str)] = &[
    ("common/layout.wgsl", include_str!("../../wgsl/common/layout.wgsl")),
    ("common/brdf.wgsl", include_str!("../../wgsl/common/brdf.wgsl")),
];

/// Shared WGSL that declares bindings (group 1), prepended only to the kernels that use it.
const FIRST_SHOT_TABLE: &str = include_str!("../../wgsl/common/first_shot_table.wgsl");

/// Whether kernel `stem` binds the first-shot table (its spec's group 1), so needs the
/// shared WGSL that declares it.
fn uses_first_shot_table(stem: &str) -> bool {
    crate::stages::SPECS.iter().any(|s| s.stem == stem && s.groups.contains(&FIRST_SHOT_TABLE_GROUP))
}

/// Every kernel of the pipeline, by stem (`wgsl/<stem>.wgsl`, `src/stages/<stem>.rs`).
pub const KERNELS: &[(&str, &str)] = &[
    ("camera_item_buffer", include_str!("../../wgsl/camera_item_buffer.wgsl")),
    ("image_estimate", include_str!("../../wgsl/image_estimate.wgsl")),
    ("light_window", include_str!("../../wgsl/light_window.wgsl")),
    ("brdf_probe", include_str!("../../wgsl/brdf_probe.wgsl")),
    ("bundle_reflect", include_str!("../../wgsl/bundle_reflect.wgsl")),
    ("bundle_visibility", include_str!("../../wgsl/bundle_visibility.wgsl")),
    ("bundle_transfer", include_str!("../../wgsl/bundle_transfer.wgsl")),
    ("bundle_finalize", include_str!("../../wgsl/bundle_finalize.wgsl")),
    ("prefix_sum", include_str!("../../wgsl/prefix_sum.wgsl")),
    ("first_shot_reduce", include_str!("../../wgsl/first_shot_reduce.wgsl")),
    ("first_shot_table", include_str!("../../wgsl/first_shot_table.wgsl")),
];

/// How a kernel reaches its paged arrays (`gpu::bindings::Binding::paged`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Paging {
    /// Every paged array of the run fits in its first page: the accessors become plain
    /// indexing of page 0 (`patches_at(i).normal` is `patches[i].normal`), so that the
    /// driver loads the one field, not the whole struct through a branch over pages, which
    /// doubled the step time on lavapipe.
    Whole,
    /// Some array spans pages: the accessors pick the page (`paged_arrays`).
    Paged,
}

impl Paging {
    /// `Paged` if any array of `bytes` per element (one per patch) for `n` elements exceeds a
    /// page of `page_bytes`.
    pub fn of(n: u64, bytes: &[u64], page_bytes: u64) -> Paging {
        if bytes.iter().any(|b| n.max(1) * b > page_bytes) { Paging::Paged } else { Paging::Whole }
    }

    /// `Paged` if either is.
    pub fn or(self, other: Paging) -> Paging {
        if self == Paging::Paged || other == Paging::Paged { Paging::Paged } else { Paging::Whole }
    }
}

/// The full source of one kernel with accessors that pick the page (`Paging::Paged`), the
/// form the binding checks read.
pub fn source(stem: &str) -> String {
    source_with(stem, Paging::Paged)
}

/// The full source of one kernel: generated header, common files, the kernel itself, then
/// the pages of its paged arrays and their accessors, or, with `Paging::Whole`, the
/// accessors' calls rewritten as indexing of the first page.
pub fn source_with(stem: &str, paging: Paging) -> String {
    let body = KERNELS
        .iter()
        .find(|(s, _)| *s == stem)
        .map(|(_, src)| *src)
        .unwrap_or_else(|| panic!("no kernel named {stem} in gpu::kernel::KERNELS"));
    let mut out = String::from("// generated from src/layout.rs\n");
    out.push_str(&layout::wgsl_constants());
    for (name, src) in COMMON {
        out.push_str(&format!("\n// ---- {name}\n"));
        out.push_str(src);
    }
    if uses_first_shot_table(stem) {
        out.push_str("\n// ---- common/first_shot_table.wgsl\n");
        out.push_str(FIRST_SHOT_TABLE);
    }
    out.push_str(&format!("\n// ---- {stem}.wgsl\n"));
    out.push_str(body);
    if let Some(spec) = crate::stages::SPECS.iter().find(|s| s.stem == stem) {
        if paging == Paging::Whole {
            for b in spec.groups.iter().flat_map(|g| g.iter()).filter(|b| b.pages > 1) {
                out = index_first_page(&out, b.name);
            }
            return out;
        }
        let pages = paged_arrays(spec, &out);
        if !pages.is_empty() {
            out.push_str("\n// ---- generated: the pages of the paged arrays (gpu::bindings::Binding)\n");
            out.push_str(&pages);
        }
    }
    out
}

/// The declarations of pages 1.. of every paged binding of `spec` and the accessors that pick
/// the page: element `i` lies in page `i / len` at `i % len`, `len` being the length of page
/// 0 (every page but the last is full). The element type and access are read from page 0's
/// declaration in `src`, which must be `var<storage, ACCESS> NAME: array<TYPE>;`.
fn paged_arrays(spec: &crate::gpu::bindings::KernelSpec, src: &str) -> String {
    use crate::gpu::bindings::entries;
    let mut out = String::new();
    for (g, group) in spec.groups.iter().enumerate() {
        let all = entries(group, Paging::Paged);
        for b in group.iter().filter(|b| b.pages > 1) {
            let name = b.name;
            let decl = format!("> {name}: array<");
            let line = src.lines().find(|l| l.contains("var<storage") && l.contains(&decl)).unwrap_or_else(|| {
                panic!("{}: no `var<storage, ...> {name}: array<...>;` for the paged binding", spec.stem)
            });
            let access = &line[line.find("var<").unwrap() + 4..line.find(&decl).unwrap()];
            let start = line.find(&decl).unwrap() + decl.len();
            let ty = &line[start..line[start..].rfind(">;").map(|e| start + e).expect("array<TYPE>;")];
            let last = b.pages - 1;
            for e in all.iter().filter(|e| e.page > 0 && e.name.starts_with(name) && group[e.index].name == name) {
                out.push_str(&format!("@group({g}) @binding({}) var<{access}> {}: array<{ty}>;\n", e.binding, e.name));
            }
            let page = |k: u32| if k == 0 { name.to_string() } else { format!("{name}_{k}") };
            let switch = |body: &dyn Fn(&str) -> String| {
                let mut s = String::from("    switch (i / n) {\n");
                for k in 1..last {
                    s.push_str(&format!("        case {k}u: {{ {} }}\n", body(&page(k))));
                }
                s.push_str(&format!("        default: {{ {} }}\n    }}\n", body(&page(last))));
                s
            };
            let head = format!("    let n = arrayLength(&{name});\n");
            if ty.starts_with("atomic<") {
                let scalar = &ty[7..ty.len() - 1];
                out.push_str(&format!(
                    "fn {name}_add(i: u32, v: {scalar}) -> {scalar} {{\n{head}    if (i < n) {{ return atomicAdd(&{name}[i], v); }}\n    let k = i % n;\n{}    return {scalar}();\n}}\n",
                    switch(&|p| format!("return atomicAdd(&{p}[k], v);"))
                ));
                continue;
            }
            out.push_str(&format!(
                "fn {name}_at(i: u32) -> {ty} {{\n{head}    if (i < n) {{ return {name}[i]; }}\n    let k = i % n;\n{}    return {ty}();\n}}\n",
                switch(&|p| format!("return {p}[k];"))
            ));
            if access.contains("read_write") {
                out.push_str(&format!(
                    "fn {name}_set(i: u32, v: {ty}) {{\n{head}    if (i < n) {{ {name}[i] = v; return; }}\n    let k = i % n;\n{}}}\n",
                    switch(&|p| format!("{p}[k] = v;"))
                ));
            }
        }
    }
    out
}

/// `src` with every call of paged array `name`'s accessors written as indexing of its first
/// page: `name_at(i)` as `name[i]`, `name_set(i, v)` as `name[i] = v` (a statement),
/// `name_add(i, v)` as `atomicAdd(&name[i], v)`. Calls nested in the arguments are rewritten
/// too.
fn index_first_page(src: &str, name: &str) -> String {
    let is_ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let mut out = String::with_capacity(src.len());
    let mut rest = src;
    'scan: while let Some(at) = rest.find(name) {
        let before_ok = rest[..at].chars().next_back().is_none_or(|c| !is_ident(c));
        let after = &rest[at + name.len()..];
        for (suffix, kind) in [("_at(", 0), ("_set(", 1), ("_add(", 2)] {
            if !(before_ok && after.starts_with(suffix)) {
                continue;
            }
            let open = at + name.len() + suffix.len();
            // The matching parenthesis and the top-level commas of the arguments.
            let (mut depth, mut commas, mut close) = (1, Vec::new(), None);
            for (k, c) in rest[open..].char_indices() {
                match c {
                    '(' | '[' => depth += 1,
                    ')' | ']' => {
                        depth -= 1;
                        if depth == 0 {
                            close = Some(open + k);
                            break;
                        }
                    }
                    ',' if depth == 1 => commas.push(open + k),
                    _ => {}
                }
            }
            let close = close.unwrap_or_else(|| panic!("`{name}{suffix}` without its closing parenthesis"));
            let mut args = Vec::new();
            let mut from = open;
            for &c in commas.iter().chain([&close]) {
                args.push(index_first_page(rest[from..c].trim(), name));
                from = c + 1;
            }
            let want = if kind == 0 { 1 } else { 2 };
            assert!(args.len() == want, "`{name}{suffix}` takes {want} arguments, given {}", args.len());
            out.push_str(&rest[..at]);
            out.push_str(&match kind {
                0 => format!("{name}[{}]", args[0]),
                1 => format!("{name}[{}] = {}", args[0], args[1]),
                _ => format!("atomicAdd(&{name}[{}], {})", args[0], args[1]),
            });
            rest = &rest[close + 1..];
            continue 'scan;
        }
        out.push_str(&rest[..at + name.len()]);
        rest = after;
    }
    out.push_str(rest);
    out
}

/// Compiles a kernel into a shader module labelled `firstshot.<stem>`.
pub fn module(device: &wgpu::Device, stem: &str, paging: Paging) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(&format!("firstshot.{stem}")),
        source: wgpu::ShaderSource::Wgsl(source_with(stem, paging).into()),
    })
}

/// Parses and validates a kernel with naga, as the unit tests do for every kernel.
pub fn validate(stem: &str) -> std::result::Result<naga::Module, String> {
    reflect(stem).map(|(module, _)| module)
}

/// The parsed kernel and naga's analysis of it (which globals each entry point uses), for
/// holding a `KernelSpec` against the WGSL (`bindings::check`).
pub fn reflect(stem: &str) -> std::result::Result<(naga::Module, naga::valid::ModuleInfo), String> {
    let src = source(stem);
    let module = naga::front::wgsl::parse_str(&src).map_err(|e| e.emit_to_string(&src))?;
    let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
        .validate(&module)
        .map_err(|e| e.emit_to_string(&src))?;
    Ok((module, info))
}

/// Records one compute dispatch of `pipeline` over `groups` workgroups (x, y) in a pass
/// labelled `label`, with `bind_groups` bound from group 0 on.
pub fn dispatch(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_groups: &[&wgpu::BindGroup],
    groups: (u32, u32),
) {
    let mut pass =
        encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes: None });
    pass.set_pipeline(pipeline);
    for (i, group) in bind_groups.iter().enumerate() {
        pass.set_bind_group(i as u32, *group, &[]);
    }
    pass.dispatch_workgroups(groups.0, groups.1, 1);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kernel_parses_and_validates() {
        for (stem, _) in KERNELS {
            if let Err(e) = validate(stem) {
                panic!("wgsl/{stem}.wgsl does not validate:\n{e}");
            }
        }
    }

    #[test]
    fn every_kernel_validates_with_its_paged_arrays_indexed_whole() {
        for (stem, _) in KERNELS {
            let src = source_with(stem, Paging::Whole);
            let module = naga::front::wgsl::parse_str(&src)
                .unwrap_or_else(|e| panic!("wgsl/{stem}.wgsl, Paging::Whole:\n{}", e.emit_to_string(&src)));
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
                .validate(&module)
                .unwrap_or_else(|e| panic!("wgsl/{stem}.wgsl, Paging::Whole:\n{}", e.emit_to_string(&src)));
            for b in
                crate::stages::SPECS.iter().filter(|s| s.stem == *stem).flat_map(|s| s.groups.iter().copied()).flatten()
            {
                if b.pages > 1 {
                    for accessor in ["_at(", "_set(", "_add("] {
                        let call = format!("{}{accessor}", b.name);
                        let left = src
                            .match_indices(&call)
                            .any(|(i, _)| !src[..i].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_'));
                        assert!(!left, "wgsl/{stem}.wgsl, Paging::Whole: a call of `{call}` is left");
                    }
                }
            }
        }
    }

    #[test]
    fn accessor_calls_become_indexing() {
        let src = "let a = p_at(i).v0.xyz + q_p_at(1u); p_set(k, p_at(f(j, 2u)));\nlet o = p_add(6u * j, low);";
        assert_eq!(
            index_first_page(src, "p"),
            "let a = p[i].v0.xyz + q_p_at(1u); p[k] = p[f(j, 2u)];\nlet o = atomicAdd(&p[6u * j], low);"
        );
    }
}
