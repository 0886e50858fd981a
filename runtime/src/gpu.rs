//! Headless rendering of a [`SceneBuffers`] scene: its buffers, the blur method's passes
//! ([`crate::blur::Method::upload`]), the shading render pass into an `Rgba32Float` target, and
//! readback (rows padded to 256 B). The device itself is [`crate::device`].

use std::time::Instant;

use wgpu::util::DeviceExt;

use crate::bindings::shade as b;
use crate::blur::{Method, Prepared};
use crate::device::map_read;
pub use crate::device::{Gpu, Timings};
use crate::layout::{Frame, LightGpu, PlaneGpu};
use crate::output::Image;
use crate::scene::SceneBuffers;
use crate::{shader, Error, Result};

/// A scene uploaded to the GPU with its pipeline: render repeatedly with [`Renderer::frame`];
/// [`Renderer::set_lights`] moves the lights without rebuilding anything.
pub struct Renderer {
    gpu: Gpu,
    pipeline: wgpu::RenderPipeline,
    /// The light buffer (`COPY_DST`: rewritten by `set_lights`) and its light count.
    lights: wgpu::Buffer,
    light_count: usize,
    /// Its shader has the Gaussian light's code (`Variant::gaussian`).
    gaussian: bool,
    /// Its shader has the turned rectangle's code (`Variant::turned_rect`).
    turned_rect: bool,
    /// Its shader has only distant lights' code (`Variant::distant_only`).
    distant_only: bool,
    /// The uniform block, and with a caster the blur method with what it prepared (asked
    /// whether moved lights keep it valid).
    frame: Frame,
    blur: Option<(&'static dyn Method, Prepared, PlaneGpu)>,
    bind_group: wgpu::BindGroup,
    target: wgpu::Texture,
    /// The uniform block's buffer (`COPY_DST`: rewritten by `set_frame`).
    uniform: wgpu::Buffer,
    /// Mesh path: the vertex buffer, its corner count and the depth buffer.
    mesh: Option<(wgpu::Buffer, u32, wgpu::Texture)>,
    /// Mesh path with the macro shadow: the depth pass, its bind group and the depth maps
    /// (one layer per light), rendered at the start of every frame.
    shadow: Option<Shadow>,
    size: [u32; 2],
    /// Setup timings (`compile`, `upload`, `sat_build`).
    pub setup: Timings,
}

/// The macro shadow's depth pass (`vs_shadow` in `shader/mesh.wgsl`) and its maps.
struct Shadow {
    pipeline: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    maps: wgpu::Texture,
}

const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

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
        if v.mesh {
            crate::mesh::check_fits(
                p.mesh_vertices.len() / 3,
                gpu.device.limits().max_buffer_size,
            )?;
        }
        let mesh_layout = [Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<crate::layout::MeshVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &crate::layout::MeshVertex::ATTRIBUTES,
        })];
        let (vs, fs, buffers, depth_stencil): (_, _, &[Option<wgpu::VertexBufferLayout>], _) =
            if v.mesh {
                (
                    "vs_mesh",
                    "fs_mesh",
                    &mesh_layout,
                    Some(wgpu::DepthStencilState {
                        format: DEPTH_FORMAT,
                        depth_write_enabled: Some(true),
                        depth_compare: Some(wgpu::CompareFunction::Less),
                        stencil: Default::default(),
                        bias: Default::default(),
                    }),
                )
            } else {
                ("vs_main", "fs_main", &[], None)
            };
        let pipeline = gpu
            .device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("shade"),
                layout: None,
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(vs),
                    compilation_options: Default::default(),
                    buffers,
                },
                primitive: Default::default(),
                depth_stencil,
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(fs),
                    compilation_options: Default::default(),
                    targets: &[Some(TARGET_FORMAT.into())],
                }),
                multiview_mask: None,
                cache: None,
            });
        let shadow_pipeline = (v.mesh && v.shadow).then(|| {
            gpu.device
                .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some("shadow maps"),
                    layout: None,
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some("vs_shadow"),
                        compilation_options: Default::default(),
                        buffers: &mesh_layout,
                    },
                    primitive: Default::default(),
                    depth_stencil: Some(wgpu::DepthStencilState {
                        format: DEPTH_FORMAT,
                        depth_write_enabled: Some(true),
                        depth_compare: Some(wgpu::CompareFunction::Less),
                        stencil: Default::default(),
                        bias: Default::default(),
                    }),
                    multisample: Default::default(),
                    fragment: None,
                    multiview_mask: None,
                    cache: None,
                })
        });
        setup.passes.push(("compile", t.elapsed().as_secs_f64()));

        let t = Instant::now();
        let uniform = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("frame"),
                contents: bytemuck::bytes_of(&p.frame),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            });
        let lights = gpu.storage_with(
            "lights",
            bytemuck::cast_slice(&p.lights),
            wgpu::BufferUsages::COPY_DST,
        );
        let mut entries = vec![
            (b::FRAME.index, uniform.clone()),
            (b::LIGHTS.index, lights.clone()),
        ];
        if v.basis.is_some() {
            entries.push((
                b::COEFFS.index,
                gpu.storage("coeffs", bytemuck::cast_slice(&p.coeffs)),
            ));
        }
        // A learned basis's table: a texture of its f32 bits as u32, (G·⌈k/4⌉) × G texels of
        // four terms (`learned_node` in shade.wgsl; the node-major buffer is already in that
        // texel order). Not with every light distant: the CPU read the table once per frame
        // (`SceneBuffers::light_terms`) and no pixel reads it, so the shader binds nothing.
        let per_pixel_table = v.basis.is_some_and(ptm_format::Basis::is_learned) && !v.distant_only;
        let learned = per_pixel_table.then(|| {
            let g = v.learned_grid;
            let quads = (p.learned.len() / 4) as u32 / (g * g);
            gpu.device
                .create_texture_with_data(
                    &gpu.queue,
                    &wgpu::TextureDescriptor {
                        label: Some("learned table"),
                        size: wgpu::Extent3d {
                            width: g * quads,
                            height: g,
                            depth_or_array_layers: 1,
                        },
                        mip_level_count: 1,
                        sample_count: 1,
                        dimension: wgpu::TextureDimension::D2,
                        format: wgpu::TextureFormat::Rgba32Uint,
                        usage: wgpu::TextureUsages::TEXTURE_BINDING,
                        view_formats: &[],
                    },
                    wgpu::util::TextureDataOrder::LayerMajor,
                    bytemuck::cast_slice(&p.learned),
                )
                .create_view(&Default::default())
        });
        if v.albedo_texture {
            entries.push((
                b::ALBEDO.index,
                gpu.storage("albedo", bytemuck::cast_slice(&p.albedo)),
            ));
        }
        if v.distant && v.basis.is_some() && !v.mesh {
            // The shader's uniform array is MAX_LIGHT_TERMS vec4s long (`prepare` keeps the
            // scene's within it): the buffer is padded to that.
            let mut terms = crate::cpu::shade::light_terms(p).to_vec();
            if terms.len() > crate::scene::MAX_LIGHT_TERMS {
                return Err(Error::Scene(format!(
                    "{} lights' per-frame terms ({} vec4s) exceed the shader's uniform block of \
                     {}: use fewer lights (Scene::prepare says how many fit)",
                    p.lights.len(),
                    terms.len(),
                    crate::scene::MAX_LIGHT_TERMS
                )));
            }
            terms.resize(crate::scene::MAX_LIGHT_TERMS, [0.0; 4]);
            let buffer = gpu
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("light terms"),
                    contents: bytemuck::cast_slice(&terms),
                    usage: wgpu::BufferUsages::UNIFORM,
                });
            entries.push((b::LIGHT_TERMS.index, buffer));
        }
        if v.glossy && v.env_size > 0 {
            entries.push((
                b::ENVIRONMENT.index,
                gpu.storage("environment", bytemuck::cast_slice(&p.environment)),
            ));
        }
        if v.basis.is_some() && v.coverage {
            entries.push((
                b::COVERAGE.index,
                gpu.storage("coverage", bytemuck::cast_slice(&p.coverage)),
            ));
        }
        if v.ptm_mip {
            entries.push((
                b::PTM_LEVELS.index,
                gpu.storage("ptm levels", bytemuck::cast_slice(&p.ptm_levels)),
            ));
        }
        if v.mesh && v.normal_map {
            entries.push((
                b::NORMAL_MAP.index,
                gpu.storage("normal map", bytemuck::cast_slice(&p.normal_map)),
            ));
        }
        let size = [p.frame.screen[0] as u32, p.frame.screen[1] as u32];
        let mesh = v.mesh.then(|| {
            let vertices = gpu
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("mesh vertices"),
                    contents: bytemuck::cast_slice(&p.mesh_vertices),
                    usage: wgpu::BufferUsages::VERTEX,
                });
            let depth = attachment(
                gpu,
                "depth",
                size,
                DEPTH_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            );
            (vertices, p.mesh_vertices.len() as u32, depth)
        });
        gpu.wait("upload")?;
        setup.passes.push(("upload", t.elapsed().as_secs_f64()));

        if let Some(blur) = v.caster {
            // The filtered image's uniform block, then whatever the method uploads and builds.
            let plane = gpu
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("plane"),
                    contents: bytemuck::bytes_of(&p.plane_gpu),
                    usage: wgpu::BufferUsages::UNIFORM,
                });
            entries.push((b::PLANE.index, plane));
            let method = crate::blur::method(blur);
            entries.extend(method.upload(gpu, &p.plane, p.prepared.as_ref(), &mut setup)?);
        }

        // The macro shadow: a depth pass over the mesh per light into one layer each of the
        // maps, which the shading pass reads (its own bind group: frame and lights only).
        let shadow = match shadow_pipeline {
            Some(pipeline) => {
                let side = p.frame.shadow_size;
                let maps = gpu.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("shadow maps"),
                    size: wgpu::Extent3d {
                        width: side,
                        height: side,
                        depth_or_array_layers: p.lights.len().max(1) as u32,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: DEPTH_FORMAT,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                });
                let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("shadow maps"),
                    layout: &pipeline.get_bind_group_layout(0),
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: b::FRAME.index,
                            resource: uniform.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: b::LIGHTS.index,
                            resource: lights.as_entire_binding(),
                        },
                    ],
                });
                Some(Shadow {
                    pipeline,
                    bind_group,
                    maps,
                })
            }
            None => None,
        };
        let shadow_view = shadow.as_ref().map(|s| {
            s.maps.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            })
        });

        let layout = pipeline.get_bind_group_layout(0);
        let mut bind_entries: Vec<wgpu::BindGroupEntry> = entries
            .iter()
            .map(|(binding, buffer)| wgpu::BindGroupEntry {
                binding: *binding,
                resource: buffer.as_entire_binding(),
            })
            .collect();
        let shadow_sampler = shadow_view.is_some().then(|| {
            gpu.device
                .create_sampler(&wgpu::SamplerDescriptor::default())
        });
        if let (Some(view), Some(sampler)) = (&shadow_view, &shadow_sampler) {
            bind_entries.push(wgpu::BindGroupEntry {
                binding: b::SHADOWS.index,
                resource: wgpu::BindingResource::TextureView(view),
            });
            bind_entries.push(wgpu::BindGroupEntry {
                binding: b::GATHER.index,
                resource: wgpu::BindingResource::Sampler(sampler),
            });
        }
        if let Some(view) = &learned {
            bind_entries.push(wgpu::BindGroupEntry {
                binding: b::LEARNED.index,
                resource: wgpu::BindingResource::TextureView(view),
            });
        }
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shade"),
            layout: &layout,
            entries: &bind_entries,
        });
        let target = attachment(
            gpu,
            "radiance",
            size,
            TARGET_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
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
            gaussian: v.gaussian,
            turned_rect: v.turned_rect,
            distant_only: v.distant_only,
            frame: p.frame,
            blur: v
                .caster
                .map(|m| (crate::blur::method(m), p.prepared.clone(), p.plane_gpu)),
            bind_group,
            target,
            uniform,
            mesh,
            shadow,
            size,
            setup,
        })
    }

    /// Rewrites the uniform block for the next [`Renderer::frame`]: a moved camera (the
    /// window's orbit). `frame` must come from the same scene prepared again
    /// ([`crate::mesh::MeshScene::prepare_frame`]); what else it changes (the variant, the
    /// buffers' sizes) needs a new renderer.
    pub fn set_frame(&mut self, frame: &Frame) {
        self.frame = *frame;
        self.gpu
            .queue
            .write_buffer(&self.uniform, 0, bytemuck::bytes_of(frame));
    }

    /// Reads the macro shadow's depth maps back (one `side`² layer per light, row 0 at the top
    /// of the light's view, z/w of the nearest surface, 1 where there is none); `None` without
    /// a macro shadow. For tests against the twin's `cpu::mesh::shadow_maps`.
    pub fn read_shadow_maps(&self) -> Result<Option<Vec<f32>>> {
        let Some(s) = &self.shadow else {
            return Ok(None);
        };
        let size = s.maps.size();
        let bytes_per_row = (size.width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let rows = size.height * size.depth_or_array_layers;
        let staging = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("shadow readback"),
            size: (bytes_per_row * rows) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        enc.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &s.maps,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::DepthOnly,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(bytes_per_row),
                    rows_per_image: Some(size.height),
                },
            },
            size,
        );
        self.gpu.queue.submit([enc.finish()]);
        let bytes = map_read(&self.gpu, &staging)?;
        let mut out = Vec::with_capacity((size.width * rows) as usize);
        for row in bytes.chunks_exact(bytes_per_row as usize) {
            out.extend(bytemuck::pod_collect_to_vec::<u8, f32>(
                &row[..(size.width * 4) as usize],
            ));
        }
        Ok(Some(out))
    }

    /// Rewrites the light buffer (`queue.write_buffer`) for the next [`Renderer::frame`], e.g.
    /// with [`crate::Scene::gpu_lights`] of the scene with its lights moved. Nothing else is
    /// rebuilt, so it refuses what would need more: another number of lights, or (separable
    /// blur) other blur radii, which follow from the lights' heights and sizes.
    pub fn set_lights(&self, lights: &[LightGpu]) -> Result<()> {
        let kept = self.blur.as_ref().is_none_or(|(m, prepared, uniform)| {
            m.keeps(prepared.as_ref(), &self.frame, uniform, lights)
        });
        if !self.gaussian && lights.iter().any(|l| l.shape == LightGpu::GAUSSIAN) {
            return Err(Error::Scene(
                "a Gaussian light needs the shader variant with its code, which this renderer \
                 was built without: rebuild the renderer"
                    .into(),
            ));
        }
        if self.distant_only || lights.iter().any(|l| l.shape == LightGpu::DISTANT) {
            return Err(Error::Scene(
                "a distant light's basis terms are evaluated once per frame from the scene \
                 (SceneBuffers::light_terms), which moving lights in place does not redo: \
                 rebuild the renderer"
                    .into(),
            ));
        }
        let turned = |l: &LightGpu| l.shape == LightGpu::RECT && l.axis[1] != 0.0;
        if !self.turned_rect && self.blur.is_some() && lights.iter().any(turned) {
            return Err(Error::Scene(
                "a turned rectangular light needs the shader variant with its code, which this \
                 renderer was built without: rebuild the renderer"
                    .into(),
            ));
        }
        if lights.len() != self.light_count || !kept {
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
        let depth_view = self
            .mesh
            .as_ref()
            .map(|(_, _, d)| d.create_view(&Default::default()));
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        if let (Some(s), Some((vertices, n, _))) = (&self.shadow, &self.mesh) {
            for li in 0..s.maps.size().depth_or_array_layers {
                let layer = s.maps.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: li,
                    array_layer_count: Some(1),
                    ..Default::default()
                });
                let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("shadow map"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &layer,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                if (li as usize) < self.light_count {
                    pass.set_pipeline(&s.pipeline);
                    pass.set_bind_group(0, &s.bind_group, &[]);
                    pass.set_vertex_buffer(0, vertices.slice(..));
                    // The instance index is the light's (vs_shadow reads lights[li]).
                    pass.draw(0..*n, li..li + 1);
                }
            }
        }
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shade"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        // The mesh path leaves alpha 0 where no triangle covers the pixel.
                        load: wgpu::LoadOp::Clear(if self.mesh.is_some() {
                            wgpu::Color::TRANSPARENT
                        } else {
                            wgpu::Color::BLACK
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: depth_view.as_ref().map(|view| {
                    wgpu::RenderPassDepthStencilAttachment {
                        view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Discard,
                        }),
                        stencil_ops: None,
                    }
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            match &self.mesh {
                Some((vertices, n, _)) => {
                    pass.set_vertex_buffer(0, vertices.slice(..));
                    pass.draw(0..*n, 0..1);
                }
                None => pass.draw(0..3, 0..1),
            }
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

/// A single-level 2D texture of `size` pixels that a pass renders into (the radiance target,
/// the mesh path's depth buffer).
fn attachment(
    gpu: &Gpu,
    label: &str,
    size: [u32; 2],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: size[0],
            height: size[1],
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}
