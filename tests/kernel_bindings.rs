//! Every kernel's `KernelSpec` (the one place its bindings and workgroup sizes are written)
//! against naga's reflection of `wgsl/<stem>.wgsl`: binding numbers, names, kinds, access
//! and sizes, entry points and workgroup sizes, and what each entry point's stage may see.

use firstshot::gpu::{bindings, kernel};
use firstshot::stages::SPECS;

#[test]
fn every_spec_matches_its_wgsl() {
    let mut errors = Vec::new();
    for spec in SPECS {
        match kernel::reflect(spec.stem) {
            Ok((module, info)) => errors.extend(bindings::check(spec, &module, &info)),
            Err(e) => errors.push(format!("wgsl/{}.wgsl does not validate:\n{e}", spec.stem)),
        }
    }
    assert!(errors.is_empty(), "KernelSpecs and WGSL disagree:\n{}", errors.join("\n"));
}

#[test]
fn every_kernel_has_one_spec() {
    for (stem, _) in kernel::KERNELS {
        let n = SPECS.iter().filter(|s| s.stem == *stem).count();
        assert_eq!(n, 1, "wgsl/{stem}.wgsl has {n} KernelSpecs in stages::SPECS, not one");
    }
    for spec in SPECS {
        assert!(
            kernel::KERNELS.iter().any(|(stem, _)| *stem == spec.stem),
            "stages::SPECS lists {}, which gpu::kernel::KERNELS does not",
            spec.stem
        );
    }
}

#[test]
fn paged_arrays_are_read_only_through_their_accessors() {
    // Page 0 of a paged array is the variable itself, so `name[i]` compiles and reads page 0
    // alone: past it, robust access returns zeros or an unrelated element, silently. Only
    // the accessors (`name_at`, `name_set`, `name_add`) select the page (gpu::bindings).
    let mut errors = Vec::new();
    for spec in SPECS {
        let text = kernel::KERNELS.iter().find(|(stem, _)| *stem == spec.stem).map(|(_, t)| *t).unwrap();
        for binding in spec.groups.iter().flat_map(|g| g.iter()).filter(|b| b.pages > 1) {
            let direct = format!("{}[", binding.name);
            let atomic = format!("&{}[", binding.name);
            for (n, line) in text.lines().enumerate() {
                let code = line.split("//").next().unwrap_or("");
                let hit = code.match_indices(&direct).any(|(at, _)| {
                    // A whole identifier: not the tail of a longer name (`my_patches[`).
                    at == 0 || !code[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_')
                });
                if hit || code.contains(&atomic) {
                    errors.push(format!(
                        "wgsl/{}.wgsl:{}: `{}` indexed directly: {}",
                        spec.stem,
                        n + 1,
                        binding.name,
                        line.trim()
                    ));
                }
            }
        }
    }
    assert!(errors.is_empty(), "paged arrays must be read through their accessors:\n{}", errors.join("\n"));
}
