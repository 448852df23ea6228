//! Adapter choice and device creation, kept apart from the work: library functions take a
//! `&Context`; only `main.rs` and tests make one.

use crate::{Error, Result};
use serde::Serialize;
use std::fmt;
use std::mem::ManuallyDrop;
use std::sync::{Arc, Mutex, MutexGuard};

/// What `--adapter` asks for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AdapterChoice {
    /// Discrete GPU, then integrated, then virtual, then a CPU adapter; Vulkan first.
    Auto,
    /// A software (CPU) adapter such as lavapipe or llvmpipe.
    Cpu,
    /// Any hardware adapter (discrete, integrated or virtual).
    Gpu,
    /// The first adapter (in `Auto` order) whose name contains this, case-insensitively, or
    /// whose backend it names.
    Name(String),
    /// The adapter at this position of `list_adapters()`. Tools need it where two adapters
    /// share a name (Mesa's llvmpipe is both the Vulkan and the GL adapter).
    Index(usize),
}

impl std::str::FromStr for AdapterChoice {
    type Err = std::convert::Infallible;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "auto" => AdapterChoice::Auto,
            "cpu" => AdapterChoice::Cpu,
            "gpu" => AdapterChoice::Gpu,
            _ => AdapterChoice::Name(s.to_string()),
        })
    }
}

/// As written on the command line (`--adapter vulkan`), for messages.
impl fmt::Display for AdapterChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AdapterChoice::Auto => write!(f, "auto"),
            AdapterChoice::Cpu => write!(f, "cpu"),
            AdapterChoice::Gpu => write!(f, "gpu"),
            AdapterChoice::Name(name) => write!(f, "{name}"),
            AdapterChoice::Index(i) => write!(f, "the adapter at position {i} of the list"),
        }
    }
}

/// An adapter as `--list-adapters` and `--stats` report it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct AdapterSummary {
    pub name: String,
    pub backend: String,
    pub device_type: String,
    pub driver: String,
}

impl AdapterSummary {
    fn of(info: &wgpu::AdapterInfo) -> Self {
        AdapterSummary {
            name: info.name.clone(),
            backend: format!("{:?}", info.backend),
            device_type: match info.device_type {
                wgpu::DeviceType::DiscreteGpu => "DiscreteGpu",
                wgpu::DeviceType::IntegratedGpu => "IntegratedGpu",
                wgpu::DeviceType::VirtualGpu => "VirtualGpu",
                wgpu::DeviceType::Cpu => "Cpu",
                wgpu::DeviceType::Other => "Other",
            }
            .to_string(),
            driver: format!("{} {}", info.driver, info.driver_info).trim().to_string(),
        }
    }

    /// A CPU adapter (lavapipe): its "GPU" memory is the host's, and it runs a compute
    /// workgroup at a time on each core.
    pub fn is_cpu(&self) -> bool {
        self.device_type == "Cpu"
    }
}

impl fmt::Display for AdapterSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({}, {})", self.name, self.backend, self.device_type)
    }
}

/// A device and its queue on the chosen adapter.
pub struct Context {
    // ManuallyDrop: `Drop for Context` releases them under DRIVER_LOCK.
    pub adapter: ManuallyDrop<wgpu::Adapter>,
    pub device: ManuallyDrop<wgpu::Device>,
    pub queue: ManuallyDrop<wgpu::Queue>,
    pub summary: AdapterSummary,
    /// The first GPU error (validation, out of memory, device lost) reported since the last
    /// `check`: wgpu reports these asynchronously, so the run collects them instead of
    /// aborting, and `check` turns them into an `Error::Gpu`.
    gpu_error: Arc<Mutex<Option<String>>>,
}

/// Held while an instance, its adapters and a device are made or released. NVIDIA's Linux
/// driver can deadlock when threads of one process do this at the same time (its Vulkan
/// and EGL devices are opened while the adapters are listed): an H100 hung the views tests
/// of four threads in a futex, every time, while each test alone passed (docs/PERFORMANCE.md,
/// "Fifth run"). One at a time costs a run nothing: it opens one device.
static DRIVER_LOCK: Mutex<()> = Mutex::new(());

/// The driver lock; a thread that panicked holding it left nothing half-made that the next
/// one could trip on (wgpu's own objects clean up on drop), so a poisoned lock is taken too.
fn driver_lock() -> MutexGuard<'static, ()> {
    DRIVER_LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn instance() -> wgpu::Instance {
    instance_for(wgpu::InstanceDescriptor::new_without_display_handle())
}

fn instance_for(mut desc: wgpu::InstanceDescriptor) -> wgpu::Instance {
    desc.backends = wgpu::Backends::all();
    // Validation layers are for development; they slow lavapipe down a lot.
    desc.flags = wgpu::InstanceFlags::empty();
    wgpu::Instance::new(desc)
}

/// Lower is preferred: hardware before software, Vulkan before the other backends.
fn preference(info: &wgpu::AdapterInfo) -> (u8, u8) {
    let kind = match info.device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    };
    let backend = match info.backend {
        wgpu::Backend::Vulkan => 0,
        wgpu::Backend::Metal => 1,
        wgpu::Backend::Dx12 => 2,
        wgpu::Backend::Gl => 3,
        _ => 4,
    };
    (kind, backend)
}

/// What the pipeline needs beyond WebGPU's downlevel baseline: compute shaders (every stage
/// but the rasterisation), storage buffers written by fragment shaders (the bundle's
/// visibility, the first shot's item buffers) and read by vertex shaders (the lights'
/// windows). An OpenGL driver older than 4.3 lacks them, though wgpu may report compute
/// shaders for one by an extension: NVIDIA's EGL adapter, which wgpu opens as OpenGL 3.3,
/// did, and failed with "Validation Error ... doesn't support COMPUTE_SHADER" at the first
/// pipeline (H200, driver 580.159.04); so `unusable` reads the OpenGL version too.
pub const REQUIRED_DOWNLEVEL: wgpu::DownlevelFlags = wgpu::DownlevelFlags::COMPUTE_SHADERS
    .union(wgpu::DownlevelFlags::FRAGMENT_WRITABLE_STORAGE)
    .union(wgpu::DownlevelFlags::VERTEX_STORAGE);

/// Why firstshot cannot run on an adapter (its `info` and downlevel `flags`), or `None` if it
/// can as far as these tell (`Context::new` also builds a compute pipeline before it takes
/// one, `cannot_compute`).
pub fn unusable(info: &wgpu::AdapterInfo, flags: wgpu::DownlevelFlags) -> Option<String> {
    let fix = USE_ANOTHER_ADAPTER;
    // wgpu's OpenGL backend compiles compute shaders only from GLSL 4.30 (ES 3.10) on, while
    // its flags count an older context with the GL_ARB_compute_shader extension as able.
    if info.backend == wgpu::Backend::Gl
        && let Some((es, version)) = gl_version(&format!("{} {}", info.driver, info.driver_info))
        && version < if es { (3, 1) } else { (4, 3) }
    {
        let (name, needed) = if es { ("OpenGL ES", "3.1") } else { ("OpenGL", "4.3") };
        return Some(format!(
            "lacks compute shaders: its driver offers {name} {}.{}, compute shaders need {needed}; {fix}",
            version.0, version.1
        ));
    }
    let missing = REQUIRED_DOWNLEVEL - flags;
    if missing.is_empty() {
        return None;
    }
    let names: Vec<&str> = [
        (wgpu::DownlevelFlags::COMPUTE_SHADERS, "compute shaders"),
        (wgpu::DownlevelFlags::FRAGMENT_WRITABLE_STORAGE, "storage writes in fragment shaders"),
        (wgpu::DownlevelFlags::VERTEX_STORAGE, "storage reads in vertex shaders"),
    ]
    .into_iter()
    .filter(|(flag, _)| missing.contains(*flag))
    .map(|(_, name)| name)
    .collect();
    Some(format!("lacks {}; {fix}", names.join(" and ")))
}

/// What an unusable adapter's message ends with.
const USE_ANOTHER_ADAPTER: &str = "use another adapter, e.g. --adapter vulkan";

/// `unusable` of a found adapter.
fn adapter_unusable(adapter: &wgpu::Adapter) -> Option<String> {
    unusable(&adapter.get_info(), adapter.get_downlevel_capabilities().flags)
}

/// The OpenGL version an OpenGL adapter's driver string starts with ("4.5 (Core Profile)
/// Mesa 22.3.6", "3.3.0 NVIDIA 580.159.04", "OpenGL ES 3.2 Mesa ..."): whether it is
/// OpenGL ES, and (major, minor).
fn gl_version(driver: &str) -> Option<(bool, (u32, u32))> {
    let text = driver.trim();
    let (es, rest) = match text.strip_prefix("OpenGL ES") {
        Some(rest) => (true, rest.trim_start()),
        None => (false, text.strip_prefix("OpenGL").unwrap_or(text).trim_start()),
    };
    let number: String = rest.chars().take_while(|c| c.is_ascii_digit() || *c == '.').collect();
    let mut parts = number.split('.');
    let major = parts.next()?.parse().ok()?;
    let minor = parts.next().and_then(|m| m.parse().ok()).unwrap_or(0);
    Some((es, (major, minor)))
}

/// Whether `device` fails to build a small compute pipeline that writes a storage buffer of
/// runtime size, as every firstshot kernel does; the validation error if so. The last guard
/// for a driver whose capabilities promise more than it compiles.
fn cannot_compute(device: &wgpu::Device) -> Option<String> {
    const PROBE: &str = "@group(0) @binding(0) var<storage, read_write> out: array<u32>;\n\
        @compute @workgroup_size(1) fn main(@builtin(global_invocation_id) id: vec3<u32>) { out[id.x] = arrayLength(&out); }";
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("firstshot.compute_probe"),
        source: wgpu::ShaderSource::Wgsl(PROBE.into()),
    });
    let _pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("firstshot.compute_probe"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let error = pollster::block_on(scope.pop())?;
    let detail = error.to_string().lines().map(str::trim).rfind(|l| !l.is_empty()).unwrap_or("").to_string();
    Some(format!("cannot build a compute pipeline ({detail}); {USE_ANOTHER_ADAPTER}"))
}

/// Every adapter wgpu finds, in the order `auto` prefers them, each with why firstshot cannot
/// run on it (`unusable`), if it cannot.
pub fn list_adapters() -> Vec<(AdapterSummary, Option<String>)> {
    let _driver = driver_lock();
    sorted_adapters(&instance()).iter().map(|a| (AdapterSummary::of(&a.get_info()), adapter_unusable(a))).collect()
}

fn sorted_adapters(instance: &wgpu::Instance) -> Vec<wgpu::Adapter> {
    let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    adapters.sort_by_key(|a| preference(&a.get_info()));
    adapters
}

fn matches(choice: &AdapterChoice, index: usize, info: &wgpu::AdapterInfo) -> bool {
    match choice {
        AdapterChoice::Auto => true,
        AdapterChoice::Cpu => info.device_type == wgpu::DeviceType::Cpu,
        AdapterChoice::Gpu => matches!(
            info.device_type,
            wgpu::DeviceType::DiscreteGpu | wgpu::DeviceType::IntegratedGpu | wgpu::DeviceType::VirtualGpu
        ),
        // A backend name (vulkan, gl, metal, dx12) also selects: lavapipe and llvmpipe share
        // a name and differ only in their backend.
        AdapterChoice::Name(part) => {
            let part = part.to_lowercase();
            info.name.to_lowercase().contains(&part) || format!("{:?}", info.backend).to_lowercase() == part
        }
        AdapterChoice::Index(i) => index == *i,
    }
}

/// Worker threads a core that firstshot asks of lavapipe and llvmpipe (the CPU adapters,
/// `set_cpu_adapter_threads`).
pub const CPU_ADAPTER_THREADS_PER_CORE: usize = 4;

/// Sets `LP_NUM_THREADS`, the worker threads of Mesa's CPU adapters (lavapipe, llvmpipe), to
/// `CPU_ADAPTER_THREADS_PER_CORE` a core where the environment does not set it; a GPU's driver
/// ignores it. Mesa's default is one a core, and a dispatch or a draw whose parts take uneven
/// time (a bundle's lines through the Sierpinski fractal against those through the empty
/// room; its pixels likewise) then leaves cores idle while the last part finishes: with eight
/// threads on two cores the Sierpinski scene's runs took 6-7 % less time (the transfer 6.5 ->
/// 5.4 ms a step, the direct light 13.7 -> 12.8 ms), the Cornell boxes' the same
/// (docs/PERFORMANCE.md, "More of lavapipe's threads"). The images are the same to the bit:
/// every sum the kernels make is exact whatever the order.
///
/// # Safety
///
/// It sets an environment variable, so no other thread may be running (`std::env::set_var`):
/// call it first thing in `main`, before the adapter is opened (Mesa reads the variable then).
pub unsafe fn set_cpu_adapter_threads() {
    if std::env::var_os("LP_NUM_THREADS").is_none() {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        // SAFETY: the caller's promise that no other thread is running.
        unsafe { std::env::set_var("LP_NUM_THREADS", (CPU_ADAPTER_THREADS_PER_CORE * cores).to_string()) };
    }
}

impl Context {
    /// Opens a device on the first adapter that fits `choice`, with the adapter's own limits
    /// (large scenes need them) and no optional features: the portable path needs none.
    pub fn new(choice: &AdapterChoice) -> Result<Context> {
        Self::new_with_features(choice, wgpu::Features::empty())
    }

    /// `Context::new` on a second thread while `work` runs on this one, and both results.
    /// Opening the adapter is mostly loading and starting its driver (about 30 ms for
    /// lavapipe), and the scene's tessellation is host work of the same order: the command
    /// line does them side by side, as a CPU adapter's threads are idle until the first
    /// upload. The caller reports `work`'s errors first, as it did when the two ran in turn.
    pub fn open_while<T: Send>(choice: &AdapterChoice, work: impl FnOnce() -> T) -> (Result<Context>, T) {
        std::thread::scope(|s| {
            let opening = s.spawn(|| Context::new(choice));
            let done = work();
            let ctx = crate::joined(opening);
            (ctx, done)
        })
    }

    /// As `new`, with those of the `wanted` optional features that the adapter has (tools
    /// such as the benchmark harness ask for timestamp queries); `features()` says which
    /// were enabled. Nothing in the library depends on them.
    pub fn new_with_features(choice: &AdapterChoice, wanted: wgpu::Features) -> Result<Context> {
        let _driver = driver_lock();
        Self::open(&instance(), choice, wanted, None)
    }

    /// As `new`, for a window (the viewer): the adapter must be able to present to it, and
    /// the window's surface comes with the context (a surface belongs to the instance that
    /// made it, which must be the adapter's).
    pub fn with_window<W>(choice: &AdapterChoice, window: W) -> Result<(Context, wgpu::Surface<'static>)>
    where
        W: wgpu::WindowHandle + wgpu::rwh::HasDisplayHandle + Clone + std::fmt::Debug + 'static,
    {
        let _driver = driver_lock();
        let instance = instance_for(wgpu::InstanceDescriptor::new_with_display_handle(Box::new(window.clone())));
        let surface = instance
            .create_surface(window)
            .map_err(|e| Error::Adapter(format!("could not make a surface for the window: {e}")))?;
        let ctx = Self::open(&instance, choice, wgpu::Features::empty(), Some(&surface))?;
        Ok((ctx, surface))
    }

    fn open(
        instance: &wgpu::Instance,
        choice: &AdapterChoice,
        wanted: wgpu::Features,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<Context> {
        let adapters = sorted_adapters(instance);
        let found: Vec<String> = adapters.iter().map(|a| AdapterSummary::of(&a.get_info()).to_string()).collect();
        // Why each adapter is unusable, if it is: asked once.
        let unusable: Vec<Option<String>> = adapters.iter().map(adapter_unusable).collect();
        let any_usable = unusable.iter().any(Option::is_none);
        let mut failures = Vec::new();
        // Adapters that fit the choice but lack what the kernels need (`unusable`).
        let mut lacking = Vec::new();
        // Adapters that fit the choice but cannot draw into the window.
        let mut cannot_present = Vec::new();
        for ((_, adapter), why) in
            adapters.into_iter().enumerate().zip(unusable).filter(|((i, a), _)| matches(choice, *i, &a.get_info()))
        {
            let summary = AdapterSummary::of(&adapter.get_info());
            if surface.is_some_and(|s| !adapter.is_surface_supported(s)) {
                cannot_present.push(summary.to_string());
                continue;
            }
            // Refused here, with the reason, rather than by the first pipeline's validation.
            if let Some(why) = why {
                lacking.push(format!("{summary}: {why}"));
                continue;
            }
            let desc = wgpu::DeviceDescriptor {
                label: Some("firstshot.device"),
                required_features: wanted & adapter.features(),
                required_limits: adapter.limits(),
                ..Default::default()
            };
            match pollster::block_on(adapter.request_device(&desc)) {
                Ok((device, _)) if let Some(why) = cannot_compute(&device) => {
                    lacking.push(format!("{summary}: {why}"));
                }
                Ok((device, queue)) => {
                    let gpu_error = Arc::new(Mutex::new(None));
                    let slot = gpu_error.clone();
                    device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
                        let message = match &e {
                            wgpu::Error::OutOfMemory { .. } => format!("out of GPU memory: {e}"),
                            _ => e.to_string(),
                        };
                        record(&slot, message);
                    }));
                    let slot = gpu_error.clone();
                    device.set_device_lost_callback(move |reason, message| {
                        if reason != wgpu::DeviceLostReason::Destroyed {
                            record(&slot, format!("the device was lost ({reason:?}): {message}"));
                        }
                    });
                    return Ok(Context {
                        adapter: ManuallyDrop::new(adapter),
                        device: ManuallyDrop::new(device),
                        queue: ManuallyDrop::new(queue),
                        summary,
                        gpu_error,
                    });
                }
                Err(e) => failures.push(format!("{summary}: {e}")),
            }
        }
        // None found is the machine's problem (exit status 1); none that fits, while others
        // exist, is the choice's (a usage error, exit status 2).
        if found.is_empty() {
            return Err(Error::Adapter(format!(
                "--adapter {choice}: no GPU adapter found; install a Vulkan driver (e.g. Debian's mesa-vulkan-drivers) or an OpenGL/EGL driver"
            )));
        }
        // The choice named only adapters firstshot cannot run on while another would do: the
        // choice's problem (status 2); with none usable at all, the machine's (status 1).
        if failures.is_empty() && !lacking.is_empty() {
            let message = format!("--adapter {choice}: {}; found: {}", lacking.join("; "), found.join("; "));
            return Err(if any_usable { Error::Usage(message) } else { Error::Adapter(message) });
        }
        failures.extend(lacking);
        if failures.is_empty() && !cannot_present.is_empty() {
            return Err(Error::Adapter(format!(
                "--adapter {choice}: {} cannot draw into the window; found: {}; try another --adapter",
                cannot_present.join("; "),
                found.join("; ")
            )));
        }
        if failures.is_empty() {
            return Err(Error::Usage(format!(
                "--adapter {choice}: no adapter fits; found: {}; give auto, cpu, gpu, a backend (vulkan, gl) or part of a name that --list-adapters prints",
                found.join("; ")
            )));
        }
        Err(Error::Adapter(format!("--adapter {choice}: could not open {}", failures.join("; "))))
    }

    pub fn limits(&self) -> wgpu::Limits {
        self.device.limits()
    }

    /// The optional features the device was opened with.
    pub fn features(&self) -> wgpu::Features {
        self.device.features()
    }

    /// Waits for all submitted work; a lost device, a timeout or any GPU error reported
    /// meanwhile becomes an error.
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| Error::Gpu(format!("waiting for the GPU failed: {e}")))?;
        self.check()
    }

    /// The first GPU error reported since the last check, if any.
    pub fn check(&self) -> Result<()> {
        match self.gpu_error.lock().map(|mut e| e.take()) {
            Ok(Some(message)) => Err(Error::Gpu(message)),
            _ => Ok(()),
        }
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        let _driver = driver_lock();
        // SAFETY: each field is taken once, here, and never used again.
        unsafe {
            ManuallyDrop::drop(&mut self.queue);
            ManuallyDrop::drop(&mut self.device);
            ManuallyDrop::drop(&mut self.adapter);
        }
    }
}

fn record(slot: &Mutex<Option<String>>, message: String) {
    if let Ok(mut e) = slot.lock()
        && e.is_none()
    {
        *e = Some(message);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::DownlevelFlags as F;

    fn adapter(backend: wgpu::Backend, driver_info: &str) -> wgpu::AdapterInfo {
        wgpu::AdapterInfo {
            name: "test".into(),
            vendor: 0,
            device: 0,
            device_type: wgpu::DeviceType::Other,
            device_pci_bus_id: String::new(),
            driver: String::new(),
            driver_info: driver_info.into(),
            backend,
            subgroup_min_size: 0,
            subgroup_max_size: 0,
            transient_saves_memory: None,
            limit_bucket: None,
        }
    }

    /// What `unusable` asks of an adapter: the downlevel flags its kernels need, and on
    /// OpenGL a version whose GLSL compiles compute shaders (4.3, ES 3.1), whatever the flags
    /// say: NVIDIA's EGL adapter, "3.3.0 NVIDIA 580.159.04" in wgpu, reports compute
    /// shaders by its extension and fails at the first compute pipeline.
    #[test]
    fn adapters_without_compute_shaders_are_unusable_with_the_reason_and_the_fix() {
        let vulkan = adapter(wgpu::Backend::Vulkan, "Mesa 22.3.6");
        assert_eq!(unusable(&vulkan, F::all()), None);
        assert_eq!(unusable(&vulkan, REQUIRED_DOWNLEVEL), None);
        let none = F::all() - F::COMPUTE_SHADERS - F::FRAGMENT_WRITABLE_STORAGE - F::VERTEX_STORAGE;
        let why = unusable(&vulkan, none).expect("missing flags make it unusable");
        for part in [
            "compute shaders",
            "storage writes in fragment shaders",
            "storage reads in vertex shaders",
            "--adapter vulkan",
        ] {
            assert!(why.contains(part), "{why:?} lacks {part:?}");
        }
        let why = unusable(&vulkan, F::all() - F::VERTEX_STORAGE).expect("one missing flag is enough");
        assert!(why.contains("storage reads in vertex shaders") && !why.contains("compute shaders"), "{why}");

        let nvidia_gl = adapter(wgpu::Backend::Gl, "3.3.0 NVIDIA 580.159.04");
        let why = unusable(&nvidia_gl, F::all()).expect("OpenGL 3.3 cannot compile compute shaders");
        assert!(why.contains("OpenGL 3.3") && why.contains("need 4.3") && why.contains("--adapter vulkan"), "{why}");
        assert_eq!(unusable(&adapter(wgpu::Backend::Gl, "4.5 (Core Profile) Mesa 22.3.6"), F::all()), None);
        assert_eq!(unusable(&adapter(wgpu::Backend::Gl, "OpenGL ES 3.2 Mesa 22.3.6"), F::all()), None);
        let es30 = unusable(&adapter(wgpu::Backend::Gl, "OpenGL ES 3.0 Mesa"), F::all()).expect("ES 3.0 is unusable");
        assert!(es30.contains("OpenGL ES 3.0") && es30.contains("need 3.1"), "{es30}");
        // An unreadable version leaves the decision to the flags (and the pipeline probe).
        assert_eq!(unusable(&adapter(wgpu::Backend::Gl, "unknown"), F::all()), None);
    }

    /// The probe `Context::new` builds on each candidate adapter compiles where the kernels do.
    #[test]
    fn the_compute_probe_builds_on_an_adapter_the_tests_use() {
        let Ok(ctx) = Context::new(&AdapterChoice::Auto) else {
            assert!(std::env::var("FIRSTSHOT_REQUIRE_GPU").map_or(true, |v| v != "1"), "no adapter");
            eprintln!("SKIPPED (no GPU adapter)");
            return;
        };
        assert_eq!(cannot_compute(&ctx.device), None, "{}", ctx.summary);
    }
}
