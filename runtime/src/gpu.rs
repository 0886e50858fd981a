//! Headless wgpu: device creation, buffers of a [`SceneBuffers`] scene, the SAT compute passes,
//! the shading render pass into an `Rgba32Float` target, and readback (rows padded to 256 B).
//!
//! Timings are wall-clock seconds around each submission plus a blocking wait, so they include
//! submission overhead; on lavapipe the "GPU" is the CPU.

use std::time::Instant;

use wgpu::util::DeviceExt;

use crate::layout::{Frame, LightGpu, SatParams};
use crate::output::Image;
use crate::scene::{Blur, SceneBuffers};
use crate::{shader, Error, Result};

/// Seconds per pass, in execution order (e.g. `upload`, `sat_build`, `shade`, `readback`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Timings {
    /// (pass name, seconds) in execution order.
    pub passes: Vec<(&'static str, f64)>,
}

impl Timings {
    /// Seconds of the pass called `name`, if it ran.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.passes
            .iter()
            .find(|(n, _)| *n == name)
            .map(|&(_, s)| s)
    }
}

/// A headless device and queue (cloning shares them).
#[derive(Clone)]
pub struct Gpu {
    /// The wgpu device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Which adapter it is (name, backend, driver), for reports.
    pub adapter: wgpu::AdapterInfo,
}

impl Gpu {
    /// Opens the default adapter (honours `WGPU_BACKEND`, `WGPU_ADAPTER_NAME`,
    /// `WGPU_POWER_PREF`); on a machine without a GPU that is lavapipe ("llvmpipe").
    pub fn new() -> Result<Gpu> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
            &instance, None,
        ))
        .map_err(|e| Error::NoAdapter(e.to_string()))?;
        Gpu::from_adapter(&adapter)
    }

    /// Opens a device on `adapter` with the same features and limits as [`Gpu::new`]. For a
    /// window, pick the adapter with the window's surface as `compatible_surface` (see
    /// [`Gpu::adapter_for_surface`]) so one device both renders and presents.
    pub fn from_adapter(adapter: &wgpu::Adapter) -> Result<Gpu> {
        let info = adapter.get_info();
        // The adapter's own limits: large casters need storage buffers beyond the defaults.
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("ptm-runtime"),
            required_features: wgpu::Features::empty(),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| Error::Device {
            adapter: info.name.clone(),
            reason: e.to_string(),
        })?;
        Ok(Gpu {
            device,
            queue,
            adapter: info,
        })
    }

    /// The default adapter (same environment variables as [`Gpu::new`]) that can present to
    /// `surface`.
    pub fn adapter_for_surface(
        instance: &wgpu::Instance,
        surface: &wgpu::Surface<'_>,
    ) -> Result<wgpu::Adapter> {
        pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
            instance,
            Some(surface),
        ))
        .map_err(|e| Error::NoAdapter(format!("none can present to the window: {e}")))
    }

    /// "name (backend, device type)".
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.adapter.name, self.adapter.backend, self.adapter.device_type
        )
    }

    fn wait(&self, stage: &'static str) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| Error::Gpu {
                stage,
                reason: e.to_string(),
            })
    }

    fn storage(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        self.storage_with(label, bytes, wgpu::BufferUsages::empty())
    }

    /// A storage buffer with further `usage` (e.g. `COPY_DST` to rewrite it).
    fn storage_with(&self, label: &str, bytes: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
        // Storage bindings cannot be empty; a feature the scene lacks has no binding at all, but
        // e.g. zero lights still binds a (never read) buffer of at least one element.
        let padded;
        let contents = if bytes.len() < 64 {
            padded = [bytes, &[0u8; 64][bytes.len()..]].concat();
            &padded[..]
        } else {
            bytes
        };
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE | usage,
            })
    }
}

/// A scene uploaded to the GPU with its pipeline: render repeatedly with [`Renderer::frame`];
/// [`Renderer::set_lights`] moves the lights without rebuilding anything.
pub struct Renderer {
    gpu: Gpu,
    pipeline: wgpu::RenderPipeline,
    /// The light buffer (`COPY_DST`: rewritten by `set_lights`) and its light count.
    lights: wgpu::Buffer,
    light_count: usize,
    /// The uniform block, and the blur radius per light a separable variant's pre-blurred maps
    /// were made with (empty for other variants).
    frame: Frame,
    separable_radii: Vec<[f32; 2]>,
    bind_group: wgpu::BindGroup,
    target: wgpu::Texture,
    size: [u32; 2],
    /// Setup timings (`compile`, `upload`, `sat_build`).
    pub setup: Timings,
}

const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

impl Renderer {
    /// Builds the pipelines and buffers of `p`'s variant and uploads its data (a summed-area table, MIP chain or separable maps are built on the first render).
    pub fn new(gpu: &Gpu, p: &SceneBuffers) -> Result<Renderer> {
        let v = &p.variant;
        let mut setup = Timings::default();
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);

        let t = Instant::now();
        let src = shader::shade_source(v)?;
        let module = gpu
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("shade.wgsl"),
                source: wgpu::ShaderSource::Wgsl(src.into()),
            });
        let pipeline = gpu
            .device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("shade"),
                layout: None,
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
                    targets: &[Some(TARGET_FORMAT.into())],
                }),
                multiview_mask: None,
                cache: None,
            });
        setup.passes.push(("compile", t.elapsed().as_secs_f64()));

        let t = Instant::now();
        let uniform = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("frame"),
                contents: bytemuck::bytes_of(&p.frame),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let lights = gpu.storage_with(
            "lights",
            bytemuck::cast_slice(&p.lights),
            wgpu::BufferUsages::COPY_DST,
        );
        let mut entries = vec![(0u32, uniform), (1, lights.clone())];
        if v.basis.is_some() {
            entries.push((2, gpu.storage("coeffs", bytemuck::cast_slice(&p.coeffs))));
        }
        if v.albedo_texture {
            entries.push((3, gpu.storage("albedo", bytemuck::cast_slice(&p.albedo))));
        }
        let mut opacity = None;
        if v.caster.is_some() {
            let b = gpu.storage_copyable("opacity", bytemuck::cast_slice(&p.opacity));
            opacity = Some(b.clone());
            // The SAT variant reads only the table built from it.
            if v.caster == Some(Blur::Explicit) {
                entries.push((4, b));
            }
        }
        gpu.wait("upload")?;
        setup.passes.push(("upload", t.elapsed().as_secs_f64()));

        if v.caster == Some(Blur::Sat) {
            let t = Instant::now();
            let table = build_sat(
                gpu,
                opacity.as_ref().expect("caster without opacity"),
                p.frame.caster_size[0],
                p.frame.caster_size[1],
                v.sat_channels(),
            )?;
            setup.passes.push(("sat_build", t.elapsed().as_secs_f64()));
            entries.push((5, table));
        }

        if v.basis.is_some() && v.coverage {
            entries.push((
                10,
                gpu.storage("coverage", bytemuck::cast_slice(&p.coverage)),
            ));
        }
        if v.ptm_mip {
            entries.push((
                9,
                gpu.storage("ptm levels", bytemuck::cast_slice(&p.ptm_levels)),
            ));
        }
        if v.caster == Some(Blur::Mip) {
            entries.push((6, gpu.storage("mip", bytemuck::cast_slice(&p.mip))));
            entries.push((
                7,
                gpu.storage("mip levels", bytemuck::cast_slice(&p.mip_levels)),
            ));
        }
        if v.caster == Some(Blur::Separable) {
            let t = Instant::now();
            let map = separable_passes(gpu, p, opacity.as_ref().expect("caster without opacity"))?;
            setup.passes.push(("separable", t.elapsed().as_secs_f64()));
            entries.push((8, map));
        }

        let layout = pipeline.get_bind_group_layout(0);
        let bind_entries: Vec<wgpu::BindGroupEntry> = entries
            .iter()
            .map(|(binding, buffer)| wgpu::BindGroupEntry {
                binding: *binding,
                resource: buffer.as_entire_binding(),
            })
            .collect();
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shade"),
            layout: &layout,
            entries: &bind_entries,
        });
        let size = [p.frame.screen[0] as u32, p.frame.screen[1] as u32];
        let target = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("radiance"),
            size: wgpu::Extent3d {
                width: size[0],
                height: size[1],
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: TARGET_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Shader {
                variant: v.name(),
                reason: e.to_string(),
            });
        }
        Ok(Renderer {
            gpu: gpu.clone(),
            pipeline,
            lights,
            light_count: p.lights.len(),
            frame: p.frame,
            separable_radii: p.separable.radii.clone(),
            bind_group,
            target,
            size,
            setup,
        })
    }

    /// Rewrites the light buffer (`queue.write_buffer`) for the next [`Renderer::frame`], e.g.
    /// with [`crate::Scene::gpu_lights`] of the scene with its lights moved. Nothing else is
    /// rebuilt, so it refuses what would need more: another number of lights, or (separable
    /// blur) other blur radii, which follow from the lights' heights and sizes.
    pub fn set_lights(&self, lights: &[LightGpu]) -> Result<()> {
        let radii_kept = self.separable_radii.is_empty()
            || crate::separable::plan(&self.frame, lights).radii == self.separable_radii;
        if lights.len() != self.light_count || !radii_kept {
            return Err(Error::Scene(format!(
                "moving {} lights in place needs the same number of lights ({} here) and, for \
                 the separable blur, the same heights and radii: rebuild the renderer",
                lights.len(),
                self.light_count
            )));
        }
        if !lights.is_empty() {
            self.gpu
                .queue
                .write_buffer(&self.lights, 0, bytemuck::cast_slice(lights));
        }
        Ok(())
    }

    /// Renders one frame and waits for it; returns the seconds it took.
    pub fn frame(&self) -> Result<f64> {
        let t = Instant::now();
        let view = self.target.create_view(&Default::default());
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shade"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
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
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.draw(0..3, 0..1);
        }
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait("shade")?;
        Ok(t.elapsed().as_secs_f64())
    }

    /// The `Rgba32Float` target [`Renderer::frame`] draws into (usage `RENDER_ATTACHMENT |
    /// COPY_SRC`): a window copies it into a texture it can sample.
    pub fn target(&self) -> &wgpu::Texture {
        &self.target
    }

    /// Copies the last frame back (rows padded to 256 bytes on the GPU side, stripped here).
    pub fn readback(&self) -> Result<Image> {
        let [w, h] = self.size;
        let pixel_bytes = 16u32;
        let bytes_per_row = (w * pixel_bytes).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let rows = read_texture(&self.gpu, &self.target, bytes_per_row, h)?;
        let mut pixels = Vec::with_capacity((w * h) as usize);
        for row in rows.chunks_exact(bytes_per_row as usize) {
            // The Vec<u8> need not be 4-byte aligned: copy out rather than cast in place.
            let floats: Vec<f32> = bytemuck::pod_collect_to_vec(&row[..(w * pixel_bytes) as usize]);
            pixels.extend(floats.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]));
        }
        Ok(Image {
            width: w as usize,
            height: h as usize,
            pixels,
        })
    }
}

impl Gpu {
    /// A storage buffer that can also be copied from (inputs to compute passes, tests).
    fn storage_copyable(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        let contents = if bytes.is_empty() {
            &[0u8; 16][..]
        } else {
            bytes
        };
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            })
    }
}

fn read_texture(
    gpu: &Gpu,
    texture: &wgpu::Texture,
    bytes_per_row: u32,
    rows: u32,
) -> Result<Vec<u8>> {
    let size = (bytes_per_row * rows) as u64;
    let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(bytes_per_row),
                rows_per_image: Some(rows),
            },
        },
        texture.size(),
    );
    gpu.queue.submit([enc.finish()]);
    map_read(gpu, &staging)
}

fn map_read(gpu: &Gpu, staging: &wgpu::Buffer) -> Result<Vec<u8>> {
    let slice = staging.slice(..);
    slice.map_async(wgpu::MapMode::Read, |_| {});
    gpu.wait("readback")?;
    let data = slice.get_mapped_range().map_err(|e| Error::Gpu {
        stage: "readback",
        reason: e.to_string(),
    })?;
    let out = data.to_vec();
    drop(data);
    staging.unmap();
    Ok(out)
}

/// Records one compute pass of `entry` in `module` over `threads` invocations (64 per
/// workgroup, at least one workgroup) with storage/uniform `bindings` of group 0, whose
/// layout wgpu derives from what the entry point uses.
fn dispatch(
    gpu: &Gpu,
    enc: &mut wgpu::CommandEncoder,
    module: &wgpu::ShaderModule,
    entry: &str,
    bindings: &[(u32, &wgpu::Buffer)],
    threads: u32,
) {
    let pipeline = gpu
        .device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: None,
            module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        });
    let entries: Vec<wgpu::BindGroupEntry> = bindings
        .iter()
        .map(|&(binding, buffer)| wgpu::BindGroupEntry {
            binding,
            resource: buffer.as_entire_binding(),
        })
        .collect();
    let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(entry),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    });
    let mut pass = enc.begin_compute_pass(&Default::default());
    pass.set_pipeline(&pipeline);
    pass.set_bind_group(0, &bind_group, &[]);
    pass.dispatch_workgroups(threads.div_ceil(64).max(1), 1, 1);
}

/// Builds the u32 summed-area table of a packed-opacity buffer on the GPU (`sat.wgsl`).
pub fn build_sat(
    gpu: &Gpu,
    opacity: &wgpu::Buffer,
    w: u32,
    h: u32,
    channels: u32,
) -> Result<wgpu::Buffer> {
    let module = gpu
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("sat.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shader::SAT_WGSL.into()),
        });
    let params = gpu
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("sat params"),
            contents: bytemuck::bytes_of(&SatParams {
                size: [w, h],
                channels,
                pad: 0,
            }),
            usage: wgpu::BufferUsages::UNIFORM,
        });
    // wgpu zero-initialises buffers: row 0 and column 0 of the table stay 0.
    let table = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("sat"),
        size: ((w + 1) as u64 * (h + 1) as u64 * channels as u64 * 4).max(16),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    for (entry, threads) in [("sat_rows", h * channels), ("sat_columns", w * channels)] {
        // Auto layouts hold only what the entry point uses: the column pass reads no opacity.
        let mut bindings = vec![(0, &params), (2, &table)];
        if entry == "sat_rows" {
            bindings.push((1, opacity));
        }
        dispatch(gpu, &mut enc, &module, entry, &bindings, threads);
    }
    gpu.queue.submit([enc.finish()]);
    gpu.wait("sat_build")?;
    Ok(table)
}

/// Runs the separable blur passes (`separable.wgsl`) for every light; returns the padded maps.
pub fn separable_passes(
    gpu: &Gpu,
    p: &SceneBuffers,
    opacity: &wgpu::Buffer,
) -> Result<wgpu::Buffer> {
    let plan = &p.separable;
    let sep = plan.params(p.frame.caster_size, p.variant.sat_channels());
    let (h, channels, lights) = (sep.size[1], sep.channels, sep.lights);
    let [pw, ph] = sep.padded;
    let module = gpu
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("separable.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shader::SEPARABLE_WGSL.into()),
        });
    let params = gpu
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("separable params"),
            contents: bytemuck::bytes_of(&sep),
            usage: wgpu::BufferUsages::UNIFORM,
        });
    let radii = gpu.storage("separable radii", bytemuck::cast_slice(&plan.radii));
    let scratch = |label: &str, n: u64| {
        gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (n * 4).max(64),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    };
    let hmap = scratch(
        "separable h",
        lights as u64 * h as u64 * pw as u64 * channels as u64,
    );
    let vmap = scratch(
        "separable v",
        lights as u64 * ph as u64 * pw as u64 * channels as u64,
    );
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    for (entry, threads) in [
        ("sep_h", lights * h * channels),
        ("sep_v", lights * pw * channels),
    ] {
        // Auto layouts hold only what the entry point uses.
        let mut bindings = vec![(0, &params), (2, &radii), (3, &hmap)];
        if entry == "sep_h" {
            bindings.push((1, opacity));
        } else {
            bindings.push((4, &vmap));
        }
        dispatch(gpu, &mut enc, &module, entry, &bindings, threads);
    }
    gpu.queue.submit([enc.finish()]);
    gpu.wait("separable")?;
    Ok(vmap)
}

/// Builds the SAT of `opacity` on the GPU and reads it back (for tests and benchmarks).
pub fn sat_table(gpu: &Gpu, opacity: &[u32], w: u32, h: u32, channels: u32) -> Result<Vec<u32>> {
    let input = gpu.storage_copyable("opacity", bytemuck::cast_slice(opacity));
    let table = build_sat(gpu, &input, w, h, channels)?;
    let n = (w + 1) as u64 * (h + 1) as u64 * channels as u64 * 4;
    let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("sat readback"),
        size: n,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(&table, 0, &staging, 0, n);
    gpu.queue.submit([enc.finish()]);
    Ok(bytemuck::pod_collect_to_vec(&map_read(gpu, &staging)?))
}

/// Renders a prepared scene once: setup timings, then `shade` and `readback`.
pub fn render(gpu: &Gpu, p: &SceneBuffers) -> Result<(Image, Timings)> {
    let r = Renderer::new(gpu, p)?;
    let mut timings = r.setup.clone();
    timings.passes.push(("shade", r.frame()?));
    let t = Instant::now();
    let image = r.readback()?;
    timings.passes.push(("readback", t.elapsed().as_secs_f64()));
    Ok((image, timings))
}
