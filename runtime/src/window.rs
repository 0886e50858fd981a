//! `ptm preview --window` (cargo feature `window`): an interactive winit window over a [`Scene`]
//! ([`run`]) or a mesh scene ([`run_mesh`], `ptm preview --mesh … --window`).
//!
//! Dragging with the left mouse button moves the first light's x, y to the point under the
//! cursor (its height z stays; on a mesh, the point of the mesh's footprint under it); keys
//! `1`–`4` pick the blur method (explicit, sat, mip, separable), `B` cycles it (past separable
//! with a glossy receiver, which needs a kernel per pixel), `P` turns the
//! PTM on and off, `[` and `]` lower and raise a glossy receiver's roughness by 0.05 (within
//! [0, 1]), `Esc` (or closing the window) quits. On a mesh, dragging with the right button
//! or the arrow keys orbit the camera about the point it looks at (the mesh's shadow follows the
//! light: its depth maps are rendered every frame). The title shows the blur method (or the
//! mesh), the light position, PTM on/off, the glossy roughness (if any) and the last render
//! time. A glossy receiver reflects the caster in the window as in the PNG; its reflection does
//! not depend on the lights, so dragging still only rewrites the light buffer.
//!
//! A `Session` (no winit in it) keeps the headless [`Renderer`] between frames: dragging the
//! light only rewrites the light buffer (`queue.write_buffer`) and draws again; a change of blur
//! method, PTM or roughness re-prepares the scene and builds a new pipeline (and summed-area table or
//! blurred maps). Either way the renderer draws into its `Rgba32Float` target exactly the image
//! `ptm preview -o` writes for that scene. That target is copied into a
//! texture a small blit pass reads (`textureLoad`, nearest, letterboxed to keep the aspect) and
//! writes to the window's surface, scaled by 2^exposure and sRGB-encoded like the PNG. Resizing
//! only re-blits. One device does both: it is opened on an adapter chosen with the window's
//! surface as `compatible_surface`.
//!
//! [`WindowOptions::exit_after_frames`] makes the window a smoke test: after each presented
//! frame a fixed script applies the next action (every blur method, PTM off/on, a light move),
//! and the window closes after that many frames.

use std::sync::Arc;
use std::time::Instant;

use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::bindings::blit;
use crate::gpu::{Gpu, Renderer};
use crate::layout::BlitParams;
use crate::mesh::MeshScene;
use crate::output::Image;
use crate::scene::{Blur, Scene, SceneBuffers};
use crate::shader::BLIT_WGSL;
use crate::{Error, Result};

/// How the window behaves beyond the scene itself.
#[derive(Clone, Debug, Default)]
pub struct WindowOptions {
    /// Exposure in stops (linear × 2^E before sRGB encoding), as for the PNG.
    pub exposure: f32,
    /// Scripted smoke test: apply one scripted action after each presented frame and close
    /// after this many frames. `None`: interactive until the user quits.
    pub exit_after_frames: Option<u32>,
}

/// What happened in the window, for the command's JSON report.
#[derive(Clone, Debug, Default)]
pub struct WindowReport {
    /// "name (backend, device type)" of the adapter.
    pub adapter: String,
    /// The surface's texture format, e.g. `Bgra8UnormSrgb`.
    pub surface_format: String,
    /// Frames presented.
    pub frames: u32,
    /// Scene renders (one per change of light, blur or PTM).
    pub renders: u32,
    /// Of those, the ones that built a pipeline (the first, and each change of blur or PTM);
    /// the others only moved the light.
    pub pipeline_builds: u32,
    /// Seconds of the last render (prepare + pipeline + shade).
    pub last_render_s: f64,
    /// The blur method when the window closed.
    pub blur: &'static str,
    /// Whether the PTM was on (rather than toggled off) when the window closed.
    pub ptm_on: bool,
    /// The dragged light's position when the window closed (world), if there was one.
    pub light: Option<[f32; 3]>,
    /// The perspective camera's eye when the window closed (world; moved by orbiting a mesh).
    pub camera: Option<[f32; 3]>,
    /// Mean linear RGB of the last rendered frame (scripted mode only; read back for tests).
    pub mean_rgb: Option<[f32; 3]>,
}

/// One user (or scripted) change.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Action {
    SetBlur(Blur),
    NextBlur,
    TogglePtm,
    /// A glossy receiver's roughness changed by this step (kept within [0, 1]); nothing
    /// without one.
    Roughness(f32),
    /// Light x, y at this point of the view, as fractions (0, 0) = top left, (1, 1) = bottom
    /// right of the picture.
    LightAt([f32; 2]),
    /// Mesh: the camera orbited about its target by these azimuth and elevation steps
    /// (radians; the elevation stays within ±85°).
    Orbit([f32; 2]),
}

/// What the user can change, applied to the base scene for each render.
#[derive(Clone, Debug)]
struct Controls {
    blur: Blur,
    ptm_on: bool,
}

/// What changed since the last render (ordered: a later kind includes the earlier).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Change {
    None,
    /// Only light positions: rewrite the light buffer.
    Lights,
    /// The camera (and maybe the lights): rewrite the uniform block and the light buffer.
    Camera,
    /// Anything else (blur method, PTM): prepare the scene and build a pipeline.
    Scene,
}

/// The window's state without winit: the base scene, the controls and the renderer kept from
/// one render to the next. Exercised headless by the tests.
struct Session {
    /// The scene as given, its first light moved by drags (and its camera by orbits); the
    /// controls are applied to a copy for each build.
    base: Scene,
    /// The mesh path: the mesh scene whose `scene` `base` stands for (swapped in to prepare).
    mesh: Option<MeshScene>,
    controls: Controls,
    renderer: Option<Renderer>,
    change: Change,
    /// Renders, and renderer (pipeline) builds among them.
    renders: u32,
    builds: u32,
}

impl Session {
    fn new(scene: Scene) -> Session {
        Session {
            controls: Controls {
                blur: scene.blur,
                ptm_on: scene.ptm.is_some(),
            },
            base: scene,
            mesh: None,
            renderer: None,
            change: Change::Scene,
            renders: 0,
            builds: 0,
        }
    }

    fn with_mesh(mut mesh: MeshScene) -> Session {
        let scene = std::mem::replace(&mut mesh.scene, Scene::without_ptm());
        let mut s = Session::new(scene);
        s.mesh = Some(mesh);
        s
    }

    /// The current scene laid out for the GPU (the whole mesh scene on the mesh path, or its
    /// uniform block and textures alone when `frame_only`).
    fn prepare(&mut self, frame_only: bool) -> Result<SceneBuffers> {
        let mut scene = self.current_scene();
        let Some(m) = self.mesh.as_mut() else {
            return scene.prepare();
        };
        std::mem::swap(&mut m.scene, &mut scene);
        let p = if frame_only {
            m.prepare_frame()
        } else {
            m.prepare().map(|(p, _)| p)
        };
        std::mem::swap(&mut m.scene, &mut scene);
        p
    }

    fn current_scene(&self) -> Scene {
        let mut s = self.base.clone();
        s.blur = self.controls.blur;
        if !self.controls.ptm_on {
            s.ptm = None;
        }
        s
    }

    fn apply(&mut self, action: Action) {
        let change = match action {
            Action::SetBlur(b) => {
                self.controls.blur = b;
                Change::Scene
            }
            Action::NextBlur => {
                let i = Blur::ALL.iter().position(|&b| b == self.controls.blur);
                self.controls.blur = Blur::ALL[i.map_or(0, |i| (i + 1) % Blur::ALL.len())];
                // A glossy receiver needs a kernel per pixel: B passes over the separable blur
                // (key 4 still picks it, and the title says why it cannot render).
                if self.base.glossy.is_some() && self.controls.blur == Blur::Separable {
                    let i = Blur::ALL.iter().position(|&b| b == Blur::Separable);
                    self.controls.blur = Blur::ALL[i.map_or(0, |i| (i + 1) % Blur::ALL.len())];
                }
                Change::Scene
            }
            Action::TogglePtm => {
                self.controls.ptm_on = !self.controls.ptm_on && self.base.ptm.is_some();
                Change::Scene
            }
            Action::Roughness(step) => {
                let Some(g) = self.base.glossy.as_mut() else {
                    return;
                };
                g.roughness = (g.roughness + step).clamp(0.0, 1.0);
                Change::Scene
            }
            Action::LightAt([fx, fy]) => {
                let [x0, y0, x1, y1] = self.base.view;
                if let Some(l) = self.base.lights.first_mut() {
                    l.position[0] = x0 + fx * (x1 - x0);
                    // Row 0 of the picture is the far edge y1.
                    l.position[1] = y1 - fy * (y1 - y0);
                }
                Change::Lights
            }
            Action::Orbit([da, de]) => {
                let Some(cam) = self
                    .base
                    .perspective
                    .as_mut()
                    .filter(|_| self.mesh.is_some())
                else {
                    return;
                };
                let d: [f32; 3] = std::array::from_fn(|k| cam.eye[k] - cam.target[k]);
                let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let limit = 85f32.to_radians();
                let az = d[1].atan2(d[0]) + da;
                let el = ((d[2] / r).clamp(-1.0, 1.0).asin() + de).clamp(-limit, limit);
                let dir = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
                cam.eye = std::array::from_fn(|k| cam.target[k] + r * dir[k]);
                Change::Camera
            }
        };
        self.change = self.change.max(change);
    }

    fn dirty(&self) -> bool {
        self.change != Change::None
    }

    /// Renders what changed: the light buffer only after drags (when there is a renderer),
    /// else a new renderer for the current scene. A scene that cannot be prepared leaves no
    /// renderer, so the next change of any kind builds again.
    fn render(&mut self, gpu: &Gpu) -> Result<&Renderer> {
        let change = std::mem::replace(&mut self.change, Change::None);
        // A moved camera: the uniform block of the scene prepared again (no vertices).
        let frame = if self.renderer.is_some() && change == Change::Camera {
            Some(self.prepare(true)?.frame)
        } else {
            None
        };
        let lights = self.base.gpu_lights();
        let kept = match (&mut self.renderer, change) {
            (Some(_), Change::None) => true,
            // Refused only if the lights need more than a buffer write: then build.
            (Some(r), Change::Lights) => r.set_lights(&lights).is_ok(),
            (Some(r), Change::Camera) => {
                let ok = r.set_lights(&lights).is_ok();
                if let (true, Some(frame)) = (ok, &frame) {
                    r.set_frame(frame);
                }
                ok
            }
            _ => false,
        };
        if !kept {
            self.renderer = None;
            let prepared = self.prepare(false)?;
            self.renderer = Some(Renderer::new(gpu, &prepared)?);
            self.builds += 1;
        }
        let renderer = self.renderer.as_ref().expect("renderer just made");
        renderer.frame()?;
        self.renders += 1;
        Ok(renderer)
    }
}

/// Mean linear RGB of an image.
fn mean_rgb(image: &Image) -> [f32; 3] {
    let n = image.pixels.len().max(1) as f32;
    let mut mean = [0f32; 3];
    for p in &image.pixels {
        for c in 0..3 {
            mean[c] += p[c] / n;
        }
    }
    mean
}

/// Opens the window on `scene` and runs until the user quits (or the script ends).
///
/// The scene's first light follows the mouse; its PTM (if any) can be toggled. Needs a display
/// (X11 or Wayland); errors name what failed.
pub fn run(scene: Scene, options: WindowOptions) -> Result<WindowReport> {
    refuse_distant(&scene)?;
    run_session(Session::new(scene), options)
}

/// As [`run`] for a mesh scene (it needs its perspective camera): the first light follows the
/// mouse over the mesh's footprint (`scene.view`), the right button or the arrow keys orbit
/// the camera, `P` toggles the PTM.
pub fn run_mesh(scene: MeshScene, options: WindowOptions) -> Result<WindowReport> {
    refuse_distant(&scene.scene)?;
    run_session(Session::with_mesh(scene), options)
}

/// A drag places the first light at the cursor, and moved lights only rewrite the light
/// buffer: a distant light has no place and (on the plane) per-frame terms that would need a
/// rebuild.
fn refuse_distant(scene: &Scene) -> Result<()> {
    match scene.lights.iter().position(|l| l.distant) {
        Some(i) => Err(Error::Scene(format!(
            "light {i} is distant: the window moves lights by placing them under the cursor; \
             preview distant lights offscreen (ptm preview without --window)"
        ))),
        None => Ok(()),
    }
}

fn run_session(session: Session, options: WindowOptions) -> Result<WindowReport> {
    let mut builder = EventLoop::builder();
    // Tests run on a worker thread; the CLI is on the main thread either way.
    #[cfg(target_os = "linux")]
    {
        winit::platform::x11::EventLoopBuilderExtX11::with_any_thread(&mut builder, true);
        winit::platform::wayland::EventLoopBuilderExtWayland::with_any_thread(&mut builder, true);
    }
    let event_loop = builder.build().map_err(|e| window_error("event loop", e))?;
    let mut app = App {
        session,
        options,
        state: None,
        error: None,
        report: WindowReport::default(),
        dragging: false,
        orbiting: None,
        cursor: None,
        script_step: 0,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| window_error("event loop", e))?;
    if let Some(e) = app.error {
        return Err(e);
    }
    let scene = app.session.current_scene();
    app.report.renders = app.session.renders;
    app.report.pipeline_builds = app.session.builds;
    app.report.blur = scene.blur.name();
    app.report.ptm_on = scene.ptm.is_some();
    app.report.light = scene.lights.first().map(|l| l.position);
    app.report.camera = scene.perspective.map(|c| c.eye);
    Ok(app.report)
}

fn window_error(stage: &'static str, e: impl std::fmt::Display) -> Error {
    Error::Gpu {
        stage,
        reason: format!("{e} (the preview window needs an X11 or Wayland display)"),
    }
}

struct App {
    session: Session,
    options: WindowOptions,
    state: Option<State>,
    error: Option<Error>,
    report: WindowReport,
    dragging: bool,
    /// Mesh: where the right-button drag that orbits the camera was last seen.
    orbiting: Option<PhysicalPosition<f64>>,
    cursor: Option<PhysicalPosition<f64>>,
    script_step: u32,
}

/// Orbit per window pixel dragged (radians), and per arrow key press.
const ORBIT_PER_PIXEL: f32 = 0.01;
const ORBIT_PER_KEY: f32 = 0.1745;
/// Roughness per `[` or `]` press.
const ROUGHNESS_PER_KEY: f32 = 0.05;

/// The window and everything on the GPU (created in `resumed`).
struct State {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    gpu: Gpu,
    blit: Blit,
    /// The last rendered frame (`Rgba32Float`, sampled by the blit) and its bind group.
    frame: Option<(wgpu::Texture, wgpu::BindGroup)>,
}

impl App {
    fn apply(&mut self, action: Action) {
        self.session.apply(action);
        if let Some(state) = &self.state {
            state.window.request_redraw();
        }
    }

    /// The scripted action after frame `step` (smoke tests): every blur method, PTM off and
    /// on again, the light moved, then (a mesh) the camera orbited.
    fn scripted(step: u32) -> Action {
        match step % 8 {
            0 => Action::SetBlur(Blur::ALL[0]),
            1 => Action::NextBlur,
            2 => Action::SetBlur(Blur::ALL[2 % Blur::ALL.len()]),
            3 => Action::SetBlur(Blur::ALL[Blur::ALL.len() - 1]),
            4 => Action::TogglePtm,
            5 => Action::LightAt([0.25, 0.25]),
            6 => Action::TogglePtm,
            _ => Action::Orbit([0.5, 0.2]),
        }
    }

    fn title(&self) -> String {
        let s = &self.session.base;
        let controls = &self.session.controls;
        let blur = if self.session.mesh.is_some() {
            "– (mesh)".to_string()
        } else if s.caster.is_some() {
            controls.blur.name().to_string()
        } else {
            format!("{} (no caster)", controls.blur.name())
        };
        let light = match s.lights.first() {
            Some(l) => format!(
                "({:.2}, {:.2}, {:.2})",
                l.position[0], l.position[1], l.position[2]
            ),
            None => "none".into(),
        };
        let ptm = match (s.ptm.is_some(), controls.ptm_on) {
            (false, _) => "none",
            (true, true) => "on",
            (true, false) => "off",
        };
        let (glossy, keys) = match (&s.glossy, self.session.mesh.is_some()) {
            (_, true) => (
                String::new(),
                "drag: light · right-drag/arrows: orbit · P: PTM · Esc: quit",
            ),
            (Some(g), false) => (
                format!(" · glossy {:.2}", g.roughness),
                "drag: light · 1-4/B: blur · P: PTM · [ ]: roughness · Esc: quit",
            ),
            (None, false) => (
                String::new(),
                "drag: light · 1-4/B: blur · P: PTM · Esc: quit",
            ),
        };
        format!(
            "ptm preview — blur {blur} · light {light} · PTM {ptm}{glossy} · {:.0} ms   [{keys}]",
            1e3 * self.report.last_render_s
        )
    }

    fn open(&mut self, event_loop: &ActiveEventLoop) -> Result<State> {
        let [w, h] = self.session.base.size;
        let attributes = Window::default_attributes()
            .with_title(self.title())
            .with_inner_size(PhysicalSize::new(w, h));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .map_err(|e| window_error("window", e))?,
        );
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle_from_env(
                Box::new(event_loop.owned_display_handle()),
            ));
        let surface = instance
            .create_surface(window.clone())
            .map_err(|e| window_error("surface", e))?;
        let adapter = Gpu::adapter_for_surface(&instance, &surface)?;
        let gpu = Gpu::from_adapter(&adapter)?;
        let caps = surface.get_capabilities(&adapter);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| f.is_srgb())
            .or(caps.formats.first().copied())
            .ok_or_else(|| window_error("surface", "the adapter offers no surface format"))?;
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            color_space: Default::default(),
            width: size.width.max(1),
            height: size.height.max(1),
            desired_maximum_frame_latency: 2,
            present_mode: wgpu::PresentMode::Fifo,
            alpha_mode: caps
                .alpha_modes
                .first()
                .copied()
                .unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: vec![],
        };
        surface.configure(&gpu.device, &config);
        let blit = Blit::new(&gpu, format);
        self.report.adapter = gpu.describe();
        self.report.surface_format = format!("{format:?}");
        window.request_redraw();
        Ok(State {
            window,
            surface,
            config,
            gpu,
            blit,
            frame: None,
        })
    }

    /// Renders what changed offscreen and keeps the result for the blit.
    fn render(&mut self) -> Result<()> {
        let scripted = self.options.exit_after_frames.is_some();
        let state = self
            .state
            .as_mut()
            .expect("render before the window opened");
        let t = Instant::now();
        let renderer = self.session.render(&state.gpu)?;
        let target = renderer.target();
        let size = target.size();
        let stale = match &state.frame {
            Some((tex, _)) => tex.size() != size,
            None => true,
        };
        if stale {
            state.frame = Some(state.blit.frame_texture(&state.gpu, size));
        }
        let (texture, _) = state.frame.as_ref().expect("frame texture just made");
        let mut enc = state.gpu.device.create_command_encoder(&Default::default());
        enc.copy_texture_to_texture(target.as_image_copy(), texture.as_image_copy(), size);
        state.gpu.queue.submit([enc.finish()]);
        if scripted {
            self.report.mean_rgb = Some(mean_rgb(&renderer.readback()?));
        }
        self.report.last_render_s = t.elapsed().as_secs_f64();
        Ok(())
    }

    fn redraw(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        if self.state.is_none() {
            return Ok(());
        }
        if self.session.dirty() {
            let title = match self.render() {
                Ok(()) => self.title(),
                // A combination the scene refuses (e.g. separable blur of a tilted caster): say
                // so in the title, keep showing the last frame, and let the user choose again.
                Err(Error::Scene(reason)) => {
                    format!("{} — cannot render: {reason}", self.title())
                }
                Err(e) => return Err(e),
            };
            let state = self.state.as_ref().expect("state checked above");
            state.window.set_title(&title);
        }
        let state = self.state.as_mut().expect("state checked above");
        let texture = match state.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) => t,
            wgpu::CurrentSurfaceTexture::Suboptimal(t) => {
                // Present this one; reconfigure before the next.
                state.window.request_redraw();
                t
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(())
            }
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                state.surface.configure(&state.gpu.device, &state.config);
                state.window.request_redraw();
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                return Err(window_error(
                    "surface",
                    "validation error acquiring the next frame",
                ))
            }
        };
        let view = texture.texture.create_view(&Default::default());
        if let Some((image, bind_group)) = &state.frame {
            state.blit.draw(
                &state.gpu,
                &view,
                bind_group,
                image.size(),
                [state.config.width, state.config.height],
                self.options.exposure,
            );
        }
        state.window.pre_present_notify();
        state.gpu.queue.present(texture);
        self.report.frames += 1;

        if let Some(n) = self.options.exit_after_frames {
            if self.report.frames >= n {
                event_loop.exit();
            } else {
                let action = App::scripted(self.script_step);
                self.script_step += 1;
                self.apply(action);
            }
        }
        Ok(())
    }

    /// The cursor as fractions of the picture (letterboxed in the window), if it is known.
    fn cursor_in_picture(&self) -> Option<[f32; 2]> {
        let state = self.state.as_ref()?;
        let p = self.cursor?;
        let [w, h] = self.session.base.size;
        let fit = Letterbox::new([w, h], [state.config.width, state.config.height]);
        Some([
            (p.x as f32 - fit.offset[0]) / fit.size[0],
            (p.y as f32 - fit.offset[1]) / fit.size[1],
        ])
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: Error) {
        self.error = Some(e);
        event_loop.exit();
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_some() {
            return;
        }
        match self.open(event_loop) {
            Ok(state) => self.state = Some(state),
            Err(e) => self.fail(event_loop, e),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(state) = &mut self.state {
                    if size.width > 0 && size.height > 0 {
                        state.config.width = size.width;
                        state.config.height = size.height;
                        state.surface.configure(&state.gpu.device, &state.config);
                        state.window.request_redraw();
                    }
                }
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw(event_loop) {
                    self.fail(event_loop, e);
                }
            }
            WindowEvent::KeyboardInput { event, .. } => {
                if event.state != ElementState::Pressed || event.repeat {
                    return;
                }
                let orbit = |a: f32, e: f32| Action::Orbit([a * ORBIT_PER_KEY, e * ORBIT_PER_KEY]);
                let action = match event.logical_key.as_ref() {
                    Key::Named(NamedKey::Escape) => {
                        event_loop.exit();
                        return;
                    }
                    Key::Named(NamedKey::ArrowLeft) => orbit(-1.0, 0.0),
                    Key::Named(NamedKey::ArrowRight) => orbit(1.0, 0.0),
                    Key::Named(NamedKey::ArrowUp) => orbit(0.0, 1.0),
                    Key::Named(NamedKey::ArrowDown) => orbit(0.0, -1.0),
                    Key::Character(c) => match c.to_ascii_lowercase().as_str() {
                        // 1, 2, …: the blur methods in the order `Blur::ALL` lists them.
                        d if blur_key(d).is_some() => Action::SetBlur(blur_key(d).unwrap()),
                        "b" => Action::NextBlur,
                        "p" => Action::TogglePtm,
                        "[" => Action::Roughness(-ROUGHNESS_PER_KEY),
                        "]" => Action::Roughness(ROUGHNESS_PER_KEY),
                        _ => return,
                    },
                    _ => return,
                };
                self.apply(action);
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                self.dragging = state == ElementState::Pressed;
                if self.dragging {
                    if let Some(at) = self.cursor_in_picture() {
                        self.apply(Action::LightAt(at));
                    }
                }
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Right,
                ..
            } => {
                self.orbiting = (state == ElementState::Pressed)
                    .then_some(self.cursor)
                    .flatten();
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = Some(position);
                if self.dragging {
                    if let Some(at) = self.cursor_in_picture() {
                        self.apply(Action::LightAt(at));
                    }
                }
                if let Some(from) = self.orbiting.replace(position) {
                    // Dragging right turns the camera left about the target (the mesh turns
                    // right under it); dragging up raises it.
                    let (dx, dy) = (position.x - from.x, position.y - from.y);
                    self.apply(Action::Orbit([
                        -(dx as f32) * ORBIT_PER_PIXEL,
                        dy as f32 * ORBIT_PER_PIXEL,
                    ]));
                }
            }
            _ => {}
        }
    }
}

/// The picture letterboxed in the window: offset and size in window pixels.
struct Letterbox {
    offset: [f32; 2],
    size: [f32; 2],
}

impl Letterbox {
    fn new(image: [u32; 2], window: [u32; 2]) -> Letterbox {
        let (iw, ih) = (image[0].max(1) as f32, image[1].max(1) as f32);
        let (ww, wh) = (window[0] as f32, window[1] as f32);
        let scale = (ww / iw).min(wh / ih);
        let size = [iw * scale, ih * scale];
        Letterbox {
            offset: [0.5 * (ww - size[0]), 0.5 * (wh - size[1])],
            size,
        }
    }
}

/// The blur method digit key `d` selects: `1` the first of [`Blur::ALL`], and so on.
fn blur_key(d: &str) -> Option<Blur> {
    let n: usize = d.parse().ok()?;
    Blur::ALL.get(n.checked_sub(1)?).copied()
}

/// Fullscreen-triangle pass (`shader/blit.wgsl`, twin `cpu::blit`): the `Rgba32Float` frame
/// (`textureLoad`, no filtering needed), letterboxed, × 2^exposure, clamped, sRGB-encoded (by
/// the shader unless the surface format is sRGB already).
struct Blit {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    /// The surface format is not sRGB: encode in the shader.
    encode: bool,
}

impl Blit {
    fn new(gpu: &Gpu, format: wgpu::TextureFormat) -> Blit {
        let device = &gpu.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("blit.wgsl"),
            source: wgpu::ShaderSource::Wgsl(BLIT_WGSL.into()),
        });
        // Explicit layout: Rgba32Float is not filterable without FLOAT32_FILTERABLE, and an
        // auto-derived layout would ask for a filterable texture.
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("blit"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: blit::FRAME.index,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: blit::PARAMS.index,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("blit"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("blit"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("blit params"),
            size: std::mem::size_of::<BlitParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Blit {
            pipeline,
            layout,
            params,
            encode: !format.is_srgb(),
        }
    }

    /// A texture to copy the renderer's target into, and its bind group.
    fn frame_texture(&self, gpu: &Gpu, size: wgpu::Extent3d) -> (wgpu::Texture, wgpu::BindGroup) {
        let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("window frame"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba32Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("blit"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: blit::FRAME.index,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: blit::PARAMS.index,
                    resource: self.params.as_entire_binding(),
                },
            ],
        });
        (texture, bind_group)
    }

    fn draw(
        &self,
        gpu: &Gpu,
        view: &wgpu::TextureView,
        bind_group: &wgpu::BindGroup,
        image: wgpu::Extent3d,
        window: [u32; 2],
        exposure: f32,
    ) {
        let fit = Letterbox::new([image.width, image.height], window);
        let params = BlitParams {
            image: [image.width as f32, image.height as f32],
            offset: fit.offset,
            fit: fit.size,
            scale: exposure.exp2(),
            encode: if self.encode { 1.0 } else { 0.0 },
        };
        gpu.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("blit"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, bind_group, &[]);
            pass.draw(0..3, 0..1);
        }
        gpu.queue.submit([enc.finish()]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Caster, Light};
    use ptm_format::{Basis, Ptm};

    #[test]
    fn fit_letterboxes_and_keeps_aspect() {
        let f = Letterbox::new([100, 50], [200, 200]);
        assert_eq!(f.size, [200.0, 100.0]);
        assert_eq!(f.offset, [0.0, 50.0]);
    }

    #[test]
    fn a_distant_light_is_refused_before_any_window_opens() {
        // No display needed: the refusal comes first.
        let mut scene = smoke_scene();
        scene.lights[0].distant = true;
        let options = WindowOptions {
            exposure: 0.0,
            exit_after_frames: Some(1),
        };
        let e = run(scene, options).unwrap_err().to_string();
        assert!(e.contains("light 0 is distant"), "{e}");
    }

    /// A 64×48 view of a constant-K PTM under one light with an opaque square caster.
    fn smoke_scene() -> Scene {
        let ptm = Ptm {
            basis: Basis::Ptm6,
            width: 4,
            height: 4,
            link: ptm_format::Link::Identity,
            uv: ptm_format::UvMap::Projected,
            mips: Vec::new(),
            coverage: None,
            tile: [1.0, 1.0],
            // K = 0.3 everywhere: the PTM darkens by 30 %.
            planes: (0..6)
                .map(|i| vec![if i == 5 { 0.3 } else { 0.0 }; 16])
                .collect(),
            learned: None,
        };
        let mut scene = Scene::over_ptm(ptm, 2, [64, 48]);
        scene.view = [0.0, 0.0, 2.0, 1.5];
        scene.lights = vec![Light {
            position: [1.0, 0.75, 2.0],
            radius: 0.1,
            rect: None,
            square_box: false,
            rect_angle_deg: 0.0,
            gaussian: None,
            distant: false,
            intensity: 4.0,
            color: [1.0, 1.0, 1.0],
        }];
        scene.caster = Some(Caster {
            width: 8,
            height: 8,
            rgba: vec![[0, 0, 0, 255]; 64],
            rect: [0.75, 0.5, 1.25, 1.0],
            elevation: 0.5,
            tilt_deg: 0.0,
        });
        scene
    }

    /// Says on the terminal that test `name` did not run and why (written to stderr directly:
    /// the harness captures `eprintln!` of passing tests). With `PTM_REQUIRE_DISPLAY=1` (set by
    /// `scripts/test.sh`, which runs these tests under Xvfb) a skip is a failure instead.
    fn skip(name: &str, why: &str) {
        if std::env::var_os("PTM_REQUIRE_DISPLAY").is_some_and(|v| v == "1") {
            panic!("{name} cannot run ({why}) but PTM_REQUIRE_DISPLAY=1");
        }
        use std::io::Write;
        let _ = writeln!(std::io::stderr(), "SKIPPED {name}: {why}");
    }

    /// The light moves by rewriting its buffer only: no pipeline build, and every frame equals
    /// a fresh render of the moved scene. Blur and PTM changes build. Headless (no winit).
    #[test]
    fn dragging_the_light_rewrites_the_light_buffer_and_builds_no_pipeline() {
        let gpu = match Gpu::new() {
            Ok(g) => g,
            Err(e) => panic!("GPU tests need a wgpu adapter (lavapipe in CI): {e}"),
        };
        for blur in Blur::ALL {
            let mut scene = smoke_scene();
            scene.blur = blur;
            let mut session = Session::new(scene);
            let mut last = session.render(&gpu).unwrap().readback().unwrap();
            assert_eq!((session.builds, session.renders), (1, 1));
            for (k, at) in [[0.25, 0.25], [0.6, 0.4], [0.9, 0.8]]
                .into_iter()
                .enumerate()
            {
                session.apply(Action::LightAt(at));
                assert_eq!(session.change, Change::Lights);
                let image = session.render(&gpu).unwrap().readback().unwrap();
                assert_eq!(
                    session.builds,
                    1,
                    "{}: drag {k} built a pipeline",
                    blur.name()
                );
                let fresh = crate::gpu::render(&gpu, &session.current_scene().prepare().unwrap())
                    .unwrap()
                    .0;
                let diff = image.max_abs_diff(&fresh).unwrap();
                assert!(
                    diff < 1e-6,
                    "{}: drag {k} vs a fresh render: {diff}",
                    blur.name()
                );
                let moved = image.max_abs_diff(&last).unwrap();
                assert!(moved > 1e-3, "{}: drag {k} changed nothing", blur.name());
                last = image;
            }
            // A drag then a blur change: one build for both.
            session.apply(Action::LightAt([0.5, 0.5]));
            session.apply(Action::NextBlur);
            assert_eq!(session.change, Change::Scene);
            session.render(&gpu).unwrap();
            session.apply(Action::TogglePtm);
            session.render(&gpu).unwrap();
            assert_eq!((session.builds, session.renders), (3, 6), "{}", blur.name());
        }
    }

    /// `smoke_scene` with a glossy cloth under a tilted caster, red on its left half and
    /// blue on its right, with a clear gap between them.
    fn glossy_scene(blur: Blur) -> Scene {
        let mut scene = smoke_scene();
        scene.blur = blur;
        let c = scene.caster.as_mut().unwrap();
        c.tilt_deg = 30.0;
        c.rgba = (0..64)
            .map(|t| match t % 8 {
                0..=2 => [220, 30, 30, 255],
                5..=7 => [30, 40, 220, 255],
                _ => [0, 0, 0, 0],
            })
            .collect();
        scene.glossy = Some(crate::scene::Glossy {
            roughness: 0.2,
            background: [0.2, 0.25, 0.35],
            f0: 0.6,
            environment: None,
        });
        scene
    }

    /// A glossy receiver in the window: every frame (the first, after drags, after `[`/`]`)
    /// equals a fresh offscreen render of the scene it shows, which reflects the caster (it
    /// differs from the matte render); drags build no pipeline, roughness changes build one.
    #[test]
    fn a_glossy_window_renders_the_offscreen_image_and_drags_without_a_build() {
        let gpu = Gpu::new().expect("GPU tests need a wgpu adapter (lavapipe in CI)");
        let fresh = |s: &Session| {
            crate::gpu::render(&gpu, &s.current_scene().prepare().unwrap())
                .unwrap()
                .0
        };
        for blur in Blur::ALL.into_iter().filter(|&b| b != Blur::Separable) {
            let name = blur.name();
            let mut session = Session::new(glossy_scene(blur));
            let first = session.render(&gpu).unwrap().readback().unwrap();
            assert!(
                first.max_abs_diff(&fresh(&session)).unwrap() < 1e-6,
                "{name}"
            );
            let mut matte = glossy_scene(blur);
            matte.glossy = None;
            let matte = crate::gpu::render(&gpu, &matte.prepare().unwrap())
                .unwrap()
                .0;
            let reflected = first.max_abs_diff(&matte).unwrap();
            assert!(reflected > 1e-2, "{name}: no reflection ({reflected})");
            let mut last = first;
            for at in [[0.2, 0.3], [0.8, 0.6]] {
                session.apply(Action::LightAt(at));
                let image = session.render(&gpu).unwrap().readback().unwrap();
                assert_eq!(session.builds, 1, "{name}: a drag built a pipeline");
                let diff = image.max_abs_diff(&fresh(&session)).unwrap();
                assert!(
                    diff < 1e-6,
                    "{name}: drag to {at:?} vs a fresh render: {diff}"
                );
                assert!(image.max_abs_diff(&last).unwrap() > 1e-3, "{name}: {at:?}");
                last = image;
            }
            for step in [ROUGHNESS_PER_KEY, -2.0 * ROUGHNESS_PER_KEY] {
                let before = session.base.glossy.as_ref().unwrap().roughness;
                session.apply(Action::Roughness(step));
                assert_eq!(session.change, Change::Scene);
                let image = session.render(&gpu).unwrap().readback().unwrap();
                let after = session.base.glossy.as_ref().unwrap().roughness;
                assert!((after - (before + step)).abs() < 1e-6, "{before} {after}");
                let diff = image.max_abs_diff(&fresh(&session)).unwrap();
                assert!(
                    diff < 1e-6,
                    "{name}: roughness {after} vs a fresh render: {diff}"
                );
                let blurred = image.max_abs_diff(&last).unwrap();
                assert!(blurred > 1e-3, "{name}: roughness {after} changed nothing");
                last = image;
            }
            assert_eq!((session.builds, session.renders), (3, 5), "{name}");
            // Kept within [0, 1].
            session.apply(Action::Roughness(5.0));
            assert_eq!(session.base.glossy.as_ref().unwrap().roughness, 1.0);
            session.apply(Action::Roughness(-5.0));
            assert_eq!(session.base.glossy.as_ref().unwrap().roughness, 0.0);
        }
        // B cycles past the separable blur, which has no kernel per pixel; key 4 picks it and
        // the scene refuses it.
        let mut session = Session::new(glossy_scene(Blur::Mip));
        session.apply(Action::NextBlur);
        assert_eq!(session.controls.blur, Blur::Explicit);
        session.render(&gpu).unwrap();
        session.apply(Action::SetBlur(Blur::Separable));
        assert!(matches!(session.render(&gpu), Err(Error::Scene(_))));
        // Without one B reaches it.
        let mut matte = Session::new(smoke_scene());
        matte.controls.blur = Blur::Mip;
        matte.apply(Action::NextBlur);
        assert_eq!(matte.controls.blur, Blur::Separable);
        // Without a glossy receiver the keys change nothing.
        let mut matte = Session::new(smoke_scene());
        matte.render(&gpu).unwrap();
        matte.apply(Action::Roughness(ROUGHNESS_PER_KEY));
        assert!(!matte.dirty() && matte.base.glossy.is_none());
    }

    /// A small shadowed drape under one light, seen in perspective (its view is the drape's
    /// footprint, where a drag puts the light).
    fn mesh_scene() -> MeshScene {
        let mut scene = smoke_scene();
        scene.caster = None;
        scene.size = [64, 48];
        scene.view = [-1.3, -1.3, 1.3, 1.3];
        scene.lights[0].position = [-1.5, -1.8, 2.5];
        scene.lights[0].intensity = 10.0;
        scene.lights[0].radius = 0.2;
        scene.perspective = Some(crate::scene::Perspective {
            eye: [0.0, -4.0, 2.4],
            target: [0.0, 0.0, 0.45],
            fov_y_deg: 40.0,
        });
        let mut m = MeshScene::plain(scene, crate::mesh::Mesh::drape(24), [2.0, 2.0]);
        m.shadow_size = 128;
        m.fill = [0.1; 3];
        m
    }

    /// On a mesh, the light moves and the camera orbits without a pipeline build, and every
    /// frame equals a fresh render of the moved scene (the shadow maps follow the light).
    #[test]
    fn on_a_mesh_the_light_moves_and_the_camera_orbits_without_a_build() {
        let gpu = Gpu::new().expect("GPU tests need a wgpu adapter (lavapipe in CI)");
        let mut session = Session::with_mesh(mesh_scene());
        let mut last = session.render(&gpu).unwrap().readback().unwrap();
        for (k, action) in [
            Action::LightAt([0.2, 0.3]),
            Action::Orbit([0.6, 0.0]),
            Action::Orbit([0.0, 0.3]),
            Action::LightAt([0.8, 0.7]),
        ]
        .into_iter()
        .enumerate()
        {
            session.apply(action);
            let image = session.render(&gpu).unwrap().readback().unwrap();
            assert_eq!(session.builds, 1, "{action:?} built a pipeline");
            let fresh = crate::gpu::render(&gpu, &session.prepare(false).unwrap())
                .unwrap()
                .0;
            let diff = image.max_abs_diff(&fresh).unwrap();
            assert!(diff < 1e-6, "step {k} {action:?} vs a fresh render: {diff}");
            let moved = image.max_abs_diff(&last).unwrap();
            assert!(moved > 1e-3, "step {k} {action:?} changed nothing");
            last = image;
        }
        let eye = session.base.perspective.unwrap().eye;
        let r = |e: [f32; 3]| ((e[0]).powi(2) + (e[1]).powi(2) + (e[2] - 0.45).powi(2)).sqrt();
        assert!((r(eye) - r([0.0, -4.0, 2.4])).abs() < 1e-4, "{eye:?}");
        // The plane has no orbit: the camera stays.
        let mut plane = Session::new(smoke_scene());
        plane.apply(Action::Orbit([0.5, 0.5]));
        assert_eq!(plane.change, Change::Scene, "a fresh session builds first");
    }

    /// Opens the window for a few scripted frames (every blur method, PTM off/on, a light
    /// move). Needs a display (`scripts/test.sh` runs it under Xvfb: `xvfb-run -a cargo test
    /// -p ptm-runtime --features window`) and an adapter that presents to it; without either
    /// it says SKIPPED by name.
    #[test]
    fn window_smoke_test_needs_a_display() {
        if std::env::var_os("DISPLAY").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
            skip(
                "window::tests::window_smoke_test_needs_a_display",
                "no DISPLAY or WAYLAND_DISPLAY (run under xvfb-run -a)",
            );
            return;
        }
        let options = WindowOptions {
            exposure: 0.0,
            exit_after_frames: Some(8),
        };
        let report = match run(smoke_scene(), options) {
            Ok(report) => report,
            Err(e @ Error::NoAdapter(_)) => {
                let why = format!("a display but {e}");
                skip("window::tests::window_smoke_test_needs_a_display", &why);
                return;
            }
            Err(e) => panic!("window runs: {e}"),
        };
        eprintln!("window report: {report:?}");
        assert_eq!(report.frames, 8);
        assert!(report.renders >= 2, "{report:?}");
        // The first render builds; the script's light move is drawn without a build unless
        // another action lands before the next render (an extra redraw, e.g. after a resize).
        assert!(
            (1..=report.renders).contains(&report.pipeline_builds),
            "{report:?}"
        );
        // The script ends with the PTM back on and the light moved to (0.5, 1.125).
        assert!(report.ptm_on);
        let light = report.light.expect("one light");
        assert!((light[0] - 0.5).abs() < 1e-5 && (light[1] - 1.125).abs() < 1e-5);
        let mean = report.mean_rgb.expect("scripted mode reads back");
        assert!(mean.iter().all(|&c| c > 0.01 && c.is_finite()), "{mean:?}");
    }

    /// The window on a mesh (`ptm preview --mesh … --window`) for nine scripted frames: the
    /// script's light move and camera orbit reach the mesh scene. winit makes one event loop
    /// per process, and the plane's smoke test has it: this test runs itself again in a child
    /// process (`PTM_WINDOW_CHILD=1`), where it opens the window.
    #[test]
    fn mesh_window_smoke_test_needs_a_display() {
        let name = "window::tests::mesh_window_smoke_test_needs_a_display";
        if std::env::var_os("DISPLAY").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
            skip(
                name,
                "no DISPLAY or WAYLAND_DISPLAY (run under xvfb-run -a)",
            );
            return;
        }
        if std::env::var_os("PTM_WINDOW_CHILD").is_none() {
            let out = std::process::Command::new(std::env::current_exe().unwrap())
                .args([name, "--exact", "--nocapture", "--test-threads=1"])
                .env("PTM_WINDOW_CHILD", "1")
                .output()
                .unwrap();
            let stderr = String::from_utf8_lossy(&out.stderr);
            let stdout = String::from_utf8_lossy(&out.stdout);
            assert!(
                out.status.success() && stdout.contains("1 passed"),
                "the child process failed:\n{stdout}\n{stderr}"
            );
            for line in stderr
                .lines()
                .filter(|l| l.starts_with("SKIPPED") || l.starts_with("mesh window report"))
            {
                eprintln!("{line}");
            }
            return;
        }
        let options = WindowOptions {
            exposure: 0.0,
            exit_after_frames: Some(9),
        };
        let report = match run_mesh(mesh_scene(), options) {
            Ok(report) => report,
            Err(e @ Error::NoAdapter(_)) => {
                skip(name, &format!("a display but {e}"));
                return;
            }
            Err(e) => panic!("window runs: {e}"),
        };
        eprintln!("mesh window report: {report:?}");
        assert_eq!(report.frames, 9);
        assert!(report.ptm_on);
        // The light went to the footprint's point at (¼, ¼) of the picture; the camera orbited.
        let light = report.light.expect("one light");
        assert!(
            (light[0] + 0.65).abs() < 1e-5 && (light[1] - 0.65).abs() < 1e-5,
            "{light:?}"
        );
        let eye = report.camera.expect("a perspective camera");
        assert!(
            (eye[0] - 0.0).abs() > 0.5,
            "the camera did not orbit: {eye:?}"
        );
        let mean = report.mean_rgb.expect("scripted mode reads back");
        assert!(mean.iter().all(|&c| c > 0.005 && c.is_finite()), "{mean:?}");
    }
}
