//! Every WGSL kernel parses and validates with naga, and the structs shared with the host
//! have the same offsets and sizes on both sides.

use firstshot::gpu::kernel;
use firstshot::layout::shared_layouts;

#[test]
fn every_kernel_validates() {
    for (stem, _) in kernel::KERNELS {
        if let Err(e) = kernel::validate(stem) {
            panic!("wgsl/{stem}.wgsl:\n{e}");
        }
    }
}

#[test]
fn every_wgsl_file_is_a_registered_kernel_or_common() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("wgsl");
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "wgsl") {
            let stem = path.file_stem().unwrap().to_str().unwrap().to_string();
            assert!(
                kernel::KERNELS.iter().any(|(s, _)| *s == stem),
                "{} is not listed in gpu::kernel::KERNELS, so nothing validates it",
                path.display()
            );
        }
    }
}

#[test]
fn layout_sync_with_wgsl() {
    // Any kernel carries the common layout; parse one and read the struct layouts.
    let module = kernel::validate("image_estimate").unwrap();
    for (name, size, fields) in shared_layouts() {
        let (_, ty) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("struct {name} missing from wgsl/common/layout.wgsl"));
        let naga::TypeInner::Struct { members, span } = &ty.inner else {
            panic!("{name} is not a struct in WGSL");
        };
        assert_eq!(*span as usize, size, "size of {name}: WGSL {span}, Rust {size}");
        for (field, offset) in fields {
            let member = members
                .iter()
                .find(|m| m.name.as_deref() == Some(field))
                .unwrap_or_else(|| panic!("{name}.{field} missing in WGSL"));
            assert_eq!(
                member.offset as usize, offset,
                "offset of {name}.{field}: WGSL {}, Rust {offset}",
                member.offset
            );
        }
    }
}
