//! Where the Python with Mitsuba 3 is (`tools/mitsuba/`): one place for the harness's peers
//! study and for `tests/mitsuba.rs`, which includes this file by path.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The one command that sets the Python environment up.
pub const SETUP: &str = "tools/mitsuba/setup.sh";

/// `tools/mitsuba/` of this repository.
pub fn tools_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/mitsuba")
}

/// A Python interpreter that imports Mitsuba 3 and can run one of its variants.
#[derive(Debug, Clone)]
pub struct Python {
    pub path: PathBuf,
    pub mitsuba_version: String,
    /// The variants this build of Mitsuba has, less `llvm_ad_rgb` where no libLLVM lets it
    /// run (a GPU machine may have CUDA and no LLVM; `cuda_ad_rgb` is not probed: it needs a
    /// CUDA device, which the study finds out when it renders).
    pub variants: Vec<String>,
}

impl Python {
    /// `python tools/mitsuba/<script>` with `args`, ready to run.
    pub fn script(&self, script: &str) -> Command {
        let mut c = Command::new(&self.path);
        c.arg(tools_dir().join(script));
        c
    }
}

/// Tries `$FIRSTSHOT_PYTHON`, then `.venv/bin/python` in the repository, then `python3`; the
/// error says what was tried and how to set it up.
pub fn find_python() -> Result<Python, String> {
    let mut candidates = Vec::new();
    if let Ok(p) = std::env::var("FIRSTSHOT_PYTHON") {
        candidates.push(PathBuf::from(p));
    }
    candidates.push(Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python"));
    candidates.push(PathBuf::from("python3"));
    let probe = format!(
        "import sys; sys.path.insert(0, {:?}); import render; render.prepare_environment(); \
         import mitsuba as mi\n\
         def runs(v):\n\
         \x20   try: mi.set_variant(v); return True\n\
         \x20   except Exception: return False\n\
         usable = [v for v in mi.variants() if v != 'llvm_ad_rgb' or runs(v)]\n\
         assert usable, 'no variant of this Mitsuba runs here (llvm_ad_rgb needs libLLVM 19)'\n\
         print(mi.__version__); print(' '.join(usable))",
        tools_dir().display().to_string()
    );
    let mut tried = Vec::new();
    for c in candidates {
        match Command::new(&c).args(["-c", &probe]).output() {
            Ok(out) if out.status.success() => {
                let text = String::from_utf8_lossy(&out.stdout);
                let mut lines = text.lines();
                let mitsuba_version = lines.next().unwrap_or("?").trim().to_string();
                let variants = lines.next().unwrap_or("").split_whitespace().map(str::to_string).collect();
                return Ok(Python { path: c, mitsuba_version, variants });
            }
            Ok(out) => {
                let err = String::from_utf8_lossy(&out.stderr);
                let last = err.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").trim().to_string();
                tried.push(format!("{}: {last}", c.display()));
            }
            Err(e) => tried.push(format!("{}: {e}", c.display())),
        }
    }
    Err(format!(
        "Mitsuba 3 is not set up (tried {}). Set it up with one command: `{SETUP}` \
         (Debian's libllvm19 and a virtualenv .venv/ with tools/mitsuba/requirements.txt)",
        tried.join("; ")
    ))
}
