//! `firstshot view SCENE` (docs/CLI.md, "Viewer"): a window that shows the running image of
//! the scene, refined a few steps per frame, and a camera the mouse and keys move. The work
//! is the renderer's (`render::Renderer`, the same steps as `firstshot SCENE`): a camera move
//! only restarts the image average (`Renderer::restart_image`), while the iteration state,
//! which does not depend on the view, carries on; so the image sharpens again within a few
//! steps. With `--script FILE` the viewer follows a script instead of a person (script.rs).

mod camera;
mod display;
mod script;

use crate::cli::io::{print_stdout, say};
use crate::cli::outputs::{OutputPlan, exr_beside, exr_path};
use crate::{Failure, RenderArgs, usage};
use camera::{Direction, FlyCamera};
use clap::Args;
use display::Display;
use firstshot::gpu::context::Context;
use firstshot::image::Image;
use firstshot::render::{Hooks, NoHooks, RenderOptions, Renderer};
use firstshot::scene::{self, Camera, Patches, Scene};
use script::Command;
use std::collections::{HashSet, VecDeque};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

/// The environment variable that names a script, as `--script` does.
pub const SCRIPT_VARIABLE: &str = "FIRSTSHOT_VIEW_SCRIPT";

#[derive(Args)]
pub(crate) struct ViewArgs {
    /// Follow the commands of this file (docs/CLI.md, "Viewer") instead of the mouse and keys,
    /// then exit; default: the file named by FIRSTSHOT_VIEW_SCRIPT, if set.
    #[arg(long, value_name = "FILE")]
    script: Option<PathBuf>,
    /// Milliseconds of steps per frame: more refine faster, fewer keep the window quicker to
    /// answer (at least one step a frame).
    #[arg(long, value_name = "MS", default_value_t = 40.0)]
    frame_ms: f64,
    /// The scene, the image size (the window's), the camera to start from (--camera), the
    /// adapter and the iteration's flags, as for a render; --out names the saved images.
    #[command(flatten)]
    render: RenderArgs,
}

/// Camera speed at start, in scene widths (bounding-box diagonals) per second.
const START_SPEED: f64 = 0.25;
/// The wheel multiplies the speed by this per notch.
const WHEEL_FACTOR: f64 = 1.25;
/// Exposure change per key press, in stops.
const EXPOSURE_STEP: f64 = 0.5;
/// Most steps in one frame, whatever the budget says (a step time measured too short once).
const MAX_STEPS_PER_FRAME: u32 = 64;

/// Flags of a render that have no meaning in the viewer: refused rather than ignored.
fn refuse_render_only_flags(args: &RenderArgs) -> Result<(), Failure> {
    let given = [
        ("--iterations", args.iterations.is_some()),
        ("--time", args.time.is_some()),
        ("--all-cameras", args.all_cameras),
        ("--path", args.path.is_some()),
        ("--checkpoint-every", args.checkpoint_every.is_some()),
        ("--resume", args.resume),
        ("--shard", args.shard.is_some() || args.shard_count.is_some()),
        ("--stats", args.stats.is_some()),
        ("--list-adapters", args.list_adapters),
    ];
    match given.iter().find(|(_, g)| *g) {
        Some((flag, _)) => Err(usage(format!(
            "view: {flag} belongs to a render (firstshot SCENE {flag} ...); the viewer refines until it is closed"
        ))),
        None => Ok(()),
    }
}

pub(crate) fn run(args: ViewArgs) -> Result<(), Failure> {
    refuse_render_only_flags(&args.render)?;
    let Some(scene_path) = args.render.scene.clone() else {
        return Err(usage("view: a scene file is required (firstshot view SCENE.toml)".into()));
    };
    if !(args.frame_ms.is_finite() && args.frame_ms > 0.0 && args.frame_ms <= 10_000.0) {
        return Err(usage(format!("--frame-ms {}: expected milliseconds > 0 and at most 10000", args.frame_ms)));
    }
    let script_path = args.script.clone().or_else(|| std::env::var_os(SCRIPT_VARIABLE).map(PathBuf::from));
    let script = match &script_path {
        Some(p) => Some(script::load(p)?),
        None => None,
    };
    let mut scene = scene::load(&scene_path)?;
    if let Some(name) = &args.render.camera {
        scene.select_camera(name).map_err(|e| usage(format!("--camera {name}: {e}")))?;
    }
    let mut options = crate::render_options(&args.render, &scene)?;
    // No end: the viewer refines until it is closed (or its script ends).
    options.iterations = u32::MAX;
    firstshot::render::check_options(&scene, &options)?;
    let saves = exr_path(args.render.out.as_deref(), &scene_path)?;
    let patches = scene::tessellate(&scene, options.patch_size)?;
    let quiet = args.render.quiet;
    if !quiet {
        say(&format!(
            "loaded {}: {} patches and {} light samples",
            scene_path.display(),
            patches.patches.len(),
            patches.samples.len()
        ));
    }
    let event_loop = EventLoop::new().map_err(|e| {
        Failure::from(anyhow::anyhow!(
            "view: cannot open a window ({e}); the viewer needs a display: an X11 or Wayland session, or a virtual one (xvfb-run firstshot view ...)"
        ))
    })?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let camera = Camera { width: options.width, height: options.height, ..scene.camera };
    let speed = START_SPEED * scene_diagonal(&patches);
    // The renderer borrows the scene and the device for as long as it lives, which is the
    // rest of the process: leaking them spares the window's event handler a lifetime.
    let scene: &'static Scene = Box::leak(Box::new(scene));
    let mut app = Viewer {
        setup: Setup { scene, scene_path, patches, options, adapter: args.render.adapter.clone(), saves, quiet },
        frame_budget: Duration::from_secs_f64(args.frame_ms / 1e3),
        session: None,
        failure: None,
        camera: FlyCamera::new(camera),
        speed,
        held: HashSet::new(),
        last_frame: None,
        dragging: false,
        cursor: None,
        turn: (0.0, 0.0),
        script: script.map(VecDeque::from),
        screenshot: None,
        exposure_stops: 0.0,
        overlay: true,
        rates: Rates::default(),
    };
    event_loop.run_app(&mut app).map_err(|e| Failure::from(anyhow::anyhow!("view: the window's event loop: {e}")))?;
    if let Some(failure) = app.failure {
        return Err(failure);
    }
    if let Some(s) = &app.session
        && !quiet
    {
        let seconds = s.started.elapsed().as_secs_f64();
        // The rates past the burn-in, whose steps lack the image stages: what a person sees.
        let imaging = match s.past_burn_in {
            Some((at, frames, step)) => {
                let seconds = at.elapsed().as_secs_f64();
                format!(
                    "; past the burn-in {:.1} frames/s, {:.1} steps/s",
                    (s.frames - frames) as f64 / seconds,
                    (s.step - step) as f64 / seconds
                )
            }
            None => String::new(),
        };
        say(&format!(
            "viewer: {} frames and {} steps in {seconds:.1} s ({:.1} frames/s, {:.1} steps/s{imaging}) at {}x{} on {}",
            s.frames,
            s.step,
            s.frames as f64 / seconds,
            s.step as f64 / seconds,
            app.setup.options.width,
            app.setup.options.height,
            s.ctx.summary
        ));
    }
    Ok(())
}

/// The diagonal of the scene's bounding box (a speed that suits its size).
fn scene_diagonal(patches: &Patches) -> f64 {
    let d =
        scene::bounding_box(patches.patches.iter().flat_map(|p| p.vertices)).map_or(0.0, |(lo, hi)| (hi - lo).length());
    if d.is_finite() && d > 0.0 { d } else { 1.0 }
}

/// What the viewer was asked to show, checked before the window opened.
struct Setup {
    scene: &'static Scene,
    scene_path: PathBuf,
    patches: Patches,
    options: RenderOptions,
    adapter: firstshot::gpu::context::AdapterChoice,
    /// The EXR path that saved images are numbered after (OUT_0001.exr, ...).
    saves: PathBuf,
    quiet: bool,
}

/// The window and the render in it, made once the event loop runs.
struct Session {
    ctx: &'static Context,
    display: Display,
    renderer: Renderer<'static>,
    /// Steps run so far (burn-in included).
    step: u32,
    /// The running image as last read back, if the current view has one yet.
    image: Option<Image>,
    /// The image's automatic exposure (`Image::auto_exposure`, as a render's PNG has).
    auto_exposure: f32,
    /// Whether the texture must be made again from `image` (new steps, a new exposure).
    image_changed: bool,
    /// Measured milliseconds per step (a running mean), for the steps a frame can afford.
    step_ms: Option<f64>,
    frames: u64,
    started: Instant,
    /// When the first frame past the burn-in ended, with the frames and steps then.
    past_burn_in: Option<(Instant, u64, u32)>,
}

/// Steps and frames per second over the last second, for the overlay.
#[derive(Default)]
struct Rates {
    since: Option<Instant>,
    steps: u32,
    frames: u32,
    steps_per_second: f64,
    frames_per_second: f64,
}

impl Rates {
    fn count(&mut self, steps: u32) {
        let since = *self.since.get_or_insert_with(Instant::now);
        self.steps += steps;
        self.frames += 1;
        let seconds = since.elapsed().as_secs_f64();
        if seconds >= 1.0 {
            self.steps_per_second = self.steps as f64 / seconds;
            self.frames_per_second = self.frames as f64 / seconds;
            (self.steps, self.frames, self.since) = (0, 0, Some(Instant::now()));
        }
    }
}

struct Viewer {
    setup: Setup,
    frame_budget: Duration,
    session: Option<Session>,
    /// What ended the session early, to return from `run`.
    failure: Option<Failure>,
    camera: FlyCamera,
    /// Scene units per second.
    speed: f64,
    /// Movement keys held down.
    held: HashSet<KeyCode>,
    /// When the last frame began (the time a held key moves for).
    last_frame: Option<Instant>,
    /// Whether the left button is down (the mouse turns the camera).
    dragging: bool,
    /// The cursor's last position in the window, if it has been seen.
    cursor: Option<(f64, f64)>,
    /// Degrees to turn (right, up) before the next frame, from the mouse.
    turn: (f64, f64),
    /// The script's commands left, with their line numbers; `None`: a person steers.
    script: Option<VecDeque<(usize, Command)>>,
    /// A screenshot to take at the next frame drawn, and where to write it.
    screenshot: Option<PathBuf>,
    exposure_stops: f64,
    overlay: bool,
    rates: Rates,
}

/// The direction a movement key moves the camera in.
fn movement(key: KeyCode) -> Option<Direction> {
    Some(match key {
        KeyCode::KeyW => Direction::Forward,
        KeyCode::KeyS => Direction::Back,
        KeyCode::KeyA => Direction::Left,
        KeyCode::KeyD => Direction::Right,
        KeyCode::KeyE => Direction::Up,
        KeyCode::KeyQ => Direction::Down,
        _ => return None,
    })
}

impl ApplicationHandler for Viewer {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.session.is_some() {
            return;
        }
        match self.open(event_loop) {
            Ok(session) => self.session = Some(session),
            Err(f) => self.fail(event_loop, f),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        let Some(session) = self.session.as_mut() else { return };
        session.display.on_window_event(&event);
        let person = self.script.is_none();
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            // Keys released while another window had the focus never reach this one.
            WindowEvent::Focused(false) => {
                self.held.clear();
                self.dragging = false;
            }
            WindowEvent::Resized(size) => session.display.resize(session.ctx, size.width, size.height),
            WindowEvent::RedrawRequested => {
                if let Err(f) = self.frame(event_loop) {
                    self.fail(event_loop, f);
                }
            }
            WindowEvent::KeyboardInput { event, .. } if person => {
                let pressed = event.state == ElementState::Pressed;
                if let PhysicalKey::Code(code) = event.physical_key {
                    if movement(code).is_some() {
                        if pressed {
                            self.held.insert(code);
                        } else {
                            self.held.remove(&code);
                        }
                    }
                    // A key held down repeats: only the moves (above) follow it.
                    if !pressed || event.repeat {
                        return;
                    }
                    let result = match code {
                        KeyCode::Escape => {
                            event_loop.exit();
                            Ok(())
                        }
                        KeyCode::KeyP => self.save(),
                        KeyCode::KeyC => self.print_camera(),
                        KeyCode::KeyH => {
                            self.overlay = !self.overlay;
                            Ok(())
                        }
                        KeyCode::Digit0 | KeyCode::Numpad0 => self.set_exposure(0.0),
                        KeyCode::NumpadAdd | KeyCode::Equal => self.set_exposure(self.exposure_stops + EXPOSURE_STEP),
                        KeyCode::NumpadSubtract | KeyCode::Minus => {
                            self.set_exposure(self.exposure_stops - EXPOSURE_STEP)
                        }
                        // '+' on layouts where it is not on the '=' key.
                        _ if event.logical_key == Key::Character("+".into()) => {
                            self.set_exposure(self.exposure_stops + EXPOSURE_STEP)
                        }
                        _ => Ok(()),
                    };
                    if let Err(f) = result {
                        self.fail(event_loop, f);
                    }
                }
            }
            WindowEvent::MouseInput { state, button: MouseButton::Left, .. } if person => {
                self.dragging = state == ElementState::Pressed;
            }
            WindowEvent::CursorMoved { position, .. } if person => {
                if let (true, Some((x, y))) = (self.dragging, self.cursor) {
                    // One pixel turns by one pixel's share of the field of view.
                    let per_pixel = self.camera.camera.fov_y / session.display.window.inner_size().height.max(1) as f64;
                    self.turn.0 += (position.x - x) * per_pixel;
                    self.turn.1 -= (position.y - y) * per_pixel;
                }
                self.cursor = Some((position.x, position.y));
            }
            WindowEvent::CursorLeft { .. } => self.cursor = None,
            WindowEvent::MouseWheel { delta, .. } if person => {
                let notches = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y as f64,
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                self.speed *= WHEEL_FACTOR.powf(notches);
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, _: &ActiveEventLoop) {
        if let Some(s) = &self.session {
            s.display.window.request_redraw();
        }
    }
}

impl Viewer {
    fn fail(&mut self, event_loop: &ActiveEventLoop, failure: Failure) {
        self.failure.get_or_insert(failure);
        event_loop.exit();
    }

    /// Opens the window, the device on an adapter that can show it, and the render (the
    /// first shot runs here).
    fn open(&mut self, event_loop: &ActiveEventLoop) -> Result<Session, Failure> {
        let setup = &self.setup;
        let (width, height) = (setup.options.width, setup.options.height);
        let title = format!("firstshot view {}", setup.scene_path.display());
        let attributes = Window::default_attributes()
            .with_title(title)
            .with_inner_size(winit::dpi::PhysicalSize::new(width, height));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .map_err(|e| Failure::from(anyhow::anyhow!("view: cannot open a window: {e}")))?,
        );
        let (ctx, surface) = Context::with_window(&setup.adapter, window.clone())?;
        let ctx: &'static Context = Box::leak(Box::new(ctx));
        firstshot::render::check_limits(&ctx.limits(), &setup.patches, &setup.options)?;
        if !setup.quiet {
            say(&format!("adapter: {}", ctx.summary));
        }
        let display = Display::new(ctx, window, surface)?;
        let mut hooks = PhaseHooks { quiet: setup.quiet };
        let mut renderer = Renderer::new(ctx, setup.scene, &setup.patches, &setup.options, &mut hooks)?;
        // The viewer refines until the camera moves: its images' lengths are not known.
        renderer.set_image_steps(None);
        if !setup.quiet {
            say(&format!("showing {width}x{height} on a {:?} surface", display.format()));
        }
        Ok(Session {
            ctx,
            display,
            renderer,
            step: 0,
            image: None,
            auto_exposure: 1.0,
            image_changed: false,
            step_ms: None,
            frames: 0,
            started: Instant::now(),
            past_burn_in: None,
        })
    }

    /// Carries out the script's commands up to the next one that needs frames; returns the
    /// image steps the current view must reach this frame, if the script asks for some.
    /// Exits when the script ends.
    fn follow_script(&mut self, event_loop: &ActiveEventLoop) -> Result<(Option<u32>, bool), Failure> {
        let mut moved = false;
        if self.screenshot.is_some() {
            // The last frame was not drawn (the window was busy): no further command before it.
            return Ok((Some(0), moved));
        }
        loop {
            let Some((_, command)) = self.script.as_mut().and_then(|s| s.front().cloned()) else {
                // The script ended (or was never there: then a person steers).
                if self.script.is_some() {
                    event_loop.exit();
                }
                return Ok((None, moved));
            };
            let session = self.session.as_mut().expect("a session runs the script");
            match command {
                Command::Steps(n) => {
                    if moved {
                        // The moves restart the image first: the steps begin next frame.
                        return Ok((None, moved));
                    }
                    let start = session.renderer.image_start();
                    if session.step <= start {
                        // An image asked for n steps from its start is a render's of n steps,
                        // its directions stratified over them.
                        session.renderer.set_image_steps(Some(n));
                    }
                    if session.step.saturating_sub(start) < n {
                        return Ok((Some(start.saturating_add(n)), moved));
                    }
                }
                Command::Move(direction, distance) => {
                    self.camera.translate(direction, distance);
                    moved = true;
                }
                Command::Turn(right, up) => {
                    self.camera.turn(right, up);
                    moved = true;
                }
                Command::Exposure(stops) => self.set_exposure(stops)?,
                Command::Screenshot(path) => {
                    if moved {
                        return Ok((None, moved));
                    }
                    self.screenshot = Some(path);
                    self.script.as_mut().map(VecDeque::pop_front);
                    return Ok((Some(0), moved));
                }
                Command::Save => self.save()?,
                Command::PrintCamera => self.print_camera()?,
                Command::Overlay(on) => self.overlay = on,
                Command::Quit => {
                    event_loop.exit();
                    self.script = Some(VecDeque::new());
                    return Ok((Some(0), moved));
                }
            }
            self.script.as_mut().map(VecDeque::pop_front);
        }
    }

    /// One frame: the camera's moves, a few steps, the image and the overlay.
    fn frame(&mut self, event_loop: &ActiveEventLoop) -> Result<(), Failure> {
        if self.session.is_none() {
            return Ok(());
        }
        // What to do this frame: the script's command, or the person's keys and mouse.
        let (script_end, mut moved) =
            if self.script.is_some() { self.follow_script(event_loop)? } else { (None, false) };
        if self.script.is_none() {
            // Seconds since the last frame, so that a key held moves at `speed` whatever the
            // frame rate; at most a quarter of a second, so one slow frame is no jump.
            let now = Instant::now();
            let dt = self.last_frame.map_or(0.0, |t| (now - t).as_secs_f64().min(0.25));
            self.last_frame = Some(now);
            for code in &self.held {
                if let Some(direction) = movement(*code) {
                    self.camera.translate(direction, self.speed * dt);
                    moved = true;
                }
            }
            if self.turn != (0.0, 0.0) {
                self.camera.turn(self.turn.0, self.turn.1);
                self.turn = (0.0, 0.0);
                moved = true;
            }
        }
        let budget = self.frame_budget;
        let session = self.session.as_mut().expect("checked above");
        if moved {
            session.renderer.restart_image(self.camera.camera, session.step, None);
            session.image = None;
        }
        // Steps this frame: as many as the budget affords at the measured step time.
        let affordable = match session.step_ms {
            Some(ms) => ((budget.as_secs_f64() * 1e3 / ms.max(1e-3)) as u32).clamp(1, MAX_STEPS_PER_FRAME),
            None => 1,
        };
        let end = match script_end {
            Some(end) => end.min(session.step.saturating_add(affordable)),
            None if self.script.is_some() => session.step,
            None => session.step.saturating_add(affordable),
        };
        let mut stepped = 0;
        if end > session.step {
            let t = Instant::now();
            let reached = session.renderer.advance_to(session.step, end, &mut NoHooks)?;
            stepped = reached - session.step;
            session.step = reached;
            let ms = t.elapsed().as_secs_f64() * 1e3 / stepped.max(1) as f64;
            session.step_ms = Some(session.step_ms.map_or(ms, |m| 0.7 * m + 0.3 * ms));
            if session.step > session.renderer.image_start() {
                let image = session.renderer.read_image()?;
                session.auto_exposure = image.auto_exposure();
                session.image = Some(image);
                session.image_changed = true;
            }
        }
        let exposure = self.exposure();
        let session = self.session.as_mut().expect("checked above");
        if session.image_changed
            && let Some(image) = &session.image
        {
            session.display.set_image(session.ctx, image, exposure);
            session.image_changed = false;
        }
        let lines = self.overlay.then(|| self.overlay_lines(exposure));
        let session = self.session.as_mut().expect("checked above");
        let shot = session.display.frame(session.ctx, lines.as_deref(), self.screenshot.is_some())?;
        session.frames += 1;
        if session.past_burn_in.is_none() && session.step > session.renderer.burn_in() {
            session.past_burn_in = Some((Instant::now(), session.frames, session.step));
        }
        self.rates.count(stepped);
        if let Some(shot) = shot
            && let Some(path) = self.screenshot.take()
        {
            if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
                std::fs::create_dir_all(parent)
                    .map_err(|e| Failure::from(firstshot::Error::Io { path: parent.to_path_buf(), source: e }))?;
            }
            shot.write_png(&path)?;
            if !self.setup.quiet {
                say(&format!("screenshot {}x{}: {}", shot.width, shot.height, path.display()));
            }
        }
        Ok(())
    }

    /// Exposure of the display and of saved PNGs: the automatic one of the image (as a
    /// render's PNG has) times 2^stops.
    fn exposure(&self) -> f32 {
        let auto = self.session.as_ref().filter(|s| s.image.is_some()).map_or(1.0, |s| s.auto_exposure);
        auto * 2f32.powf(self.exposure_stops as f32)
    }

    fn set_exposure(&mut self, stops: f64) -> Result<(), Failure> {
        self.exposure_stops = stops.clamp(-20.0, 20.0);
        if let Some(s) = self.session.as_mut() {
            s.image_changed = true;
        }
        Ok(())
    }

    fn overlay_lines(&self, exposure: f32) -> Vec<String> {
        let Some(s) = &self.session else { return Vec::new() };
        let start = s.renderer.image_start();
        let progress = if s.step < s.renderer.burn_in() {
            format!("burn-in {}/{}", s.step, s.renderer.burn_in())
        } else {
            format!("step {}, image of {}", s.step, s.step.saturating_sub(start))
        };
        let p = self.camera.camera.position + self.setup.scene.file_origin;
        vec![
            progress,
            format!("{:.1} steps/s, {:.1} frames/s", self.rates.steps_per_second, self.rates.frames_per_second),
            format!("exposure {exposure:.3} ({:+.1} stops)", self.exposure_stops),
            format!("camera {:.2} {:.2} {:.2}", p.x, p.y, p.z),
            format!("speed {:.3}/s", self.speed),
            "drag: look  WASD QE: move  wheel: speed".into(),
            "+/-: exposure  P: save  C: camera".into(),
            "H: hide this  Esc: quit".into(),
        ]
    }

    /// Writes the current image as OUT_NNNN.exr and its PNG (at the exposure shown), the
    /// first number whose files do not exist yet.
    fn save(&mut self) -> Result<(), Failure> {
        let exposure = self.exposure();
        let Some(s) = &self.session else { return Ok(()) };
        let Some(image) = &s.image else {
            say("save: no image yet (the burn-in is still running); try again in a moment");
            return Ok(());
        };
        let mut k = 1;
        let exr = loop {
            let exr = exr_beside(&self.setup.saves, &format!("{k:04}"), "save")?;
            if !exr.exists() && !exr.with_extension("png").exists() {
                break exr;
            }
            k += 1;
        };
        let mut plan = OutputPlan::new(&exr, None, &self.setup.scene_path, false)?;
        plan.make_folders()?;
        let steps = s.step.saturating_sub(s.renderer.image_start());
        let attributes = [
            ("firstshot.scene", self.setup.scene_path.display().to_string()),
            ("firstshot.seed", self.setup.options.seed.to_string()),
            ("firstshot.iterations", steps.to_string()),
            ("firstshot.adapter", s.ctx.summary.to_string()),
        ];
        let paths = &plan.images[0];
        image.write_exr(&paths.exr, &attributes)?;
        image.write_png(&paths.png, exposure)?;
        say(&format!("saved {} and {} ({steps} steps)", paths.exr.display(), paths.png.display()));
        Ok(())
    }

    /// Prints the camera as a `[camera]` table on standard output.
    fn print_camera(&self) -> Result<(), Failure> {
        let steps = self.session.as_ref().map_or(0, |s| s.step);
        let text = format!(
            "# firstshot view: the camera at step {steps}\n{}\n",
            self.camera.toml(self.setup.scene.file_origin)
        );
        print_stdout(&text).map_err(|e| Failure::from(anyhow::anyhow!("writing to standard output: {e}")))
    }
}

/// Says when the first shot is done (it runs before the first frame).
struct PhaseHooks {
    quiet: bool,
}

impl Hooks for PhaseHooks {
    fn phase(&mut self, name: &str, ms: f64) {
        if !self.quiet {
            say(&format!("{name}: {ms:.0} ms"));
        }
    }
}
