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
