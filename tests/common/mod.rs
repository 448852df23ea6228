//! Helpers shared by the integration tests.
#![allow(dead_code)]

use firstshot::gpu::{AdapterChoice, Context};
use std::path::PathBuf;

/// The one way tests get a GPU. With `FIRSTSHOT_REQUIRE_GPU=1` (CI) a missing adapter is a
/// failure; with `FIRSTSHOT_REQUIRE_BACKEND=vulkan` so is an adapter of another backend.
/// Elsewhere a missing adapter is a visible skip.
pub fn gpu() -> Option<Context> {
    let choice = std::env::var("FIRSTSHOT_TEST_ADAPTER")
        .map(|s| s.parse().unwrap())
        .unwrap_or(AdapterChoice::Auto);
    match Context::new(&choice) {
        Ok(ctx) => {
            if let Ok(backend) = std::env::var("FIRSTSHOT_REQUIRE_BACKEND") {
                assert!(
                    ctx.summary.backend.eq_ignore_ascii_case(&backend),
                    "FIRSTSHOT_REQUIRE_BACKEND={backend} but the test adapter is {}",
                    ctx.summary
                );
            }
            eprintln!("GPU test on adapter: {}", ctx.summary);
            Some(ctx)
        }
        Err(e) => {
            if std::env::var("FIRSTSHOT_REQUIRE_GPU").is_ok_and(|v| v == "1") {
                panic!("FIRSTSHOT_REQUIRE_GPU=1 but no adapter: {e}");
            }
            eprintln!("SKIPPED (no GPU adapter): {e}");
            None
        }
    }
}

/// `target/test-output/<name>`, created; failing image tests write their images there.
pub fn output_dir(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("target/test-output")
        .join(name);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `../shared/refs` beside the checkout, where the reference images are.
pub fn refs_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/refs")
}
