//! The GPU baker: the CPU bake's primary samples and shadow rays, traced with wgpu ray queries
//! band by band (`crate::budget`), K handed light by light to the same sink.
//!
//! Determinism: sample positions are `ptm_bake::sample_xy`'s; each texel's K is an integer count
//! of occluded samples (one invocation per texel sums its samples in order) over the covered
//! samples, so a device gives the same K on every run and for any band size.
use std::ops::Range;
use std::time::Instant;

use ptm_bake::maps::{Surface, SurfaceHit};
use ptm_bake::{tiling, BakeConfig, BakeReport, Frame, PreparedMesh, Sink, Tracer};
use ptm_format::LightSet;
use rayon::prelude::*;
use wgpu::util::DeviceExt;

use crate::adapter::Gpu;
use crate::budget;
use crate::scene::Scene;
use crate::Result;

/// The shaders of both passes (primary hits and shadow counts).
pub const SHADER: &str = include_str!("trace.wgsl");

/// GPU settings beside the bake's own ([`BakeConfig`]).
#[derive(Clone, Debug)]
pub struct GpuConfig {
    /// The most bytes of per-band buffers on the device at once (samples, hits, counts); bands
    /// shrink to fit it and the device's buffer limits.
    pub band_bytes: u64,
}

impl Default for GpuConfig {
    fn default() -> Self {
        GpuConfig {
            band_bytes: 512 << 20,
        }
    }
}

/// `PrimaryParams` in trace.wgsl, field for field.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PrimaryParams {
    /// Height of the camera plane (baker units).
    pub z_top: f32,
    /// Far end of a primary ray.
    pub t_max: f32,
    /// Footprint samples in the band.
    pub count: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}

/// `Hit` in trace.wgsl: the closest hit's distance and triangle ([`NO_HIT`]: none).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Hit {
    /// Distance along the downward ray (baker units).
    pub t: f32,
    /// The triangle hit.
    pub prim: u32,
}

/// `Hit::prim` of a primary ray that hit nothing.
pub const NO_HIT: u32 = u32::MAX;

/// `ShadowParams` in trace.wgsl, field for field.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ShadowParams {
    /// A distant light: the unit direction towards it.
    pub dir: [f32; 3],
    /// The clamp plane (baker units).
    pub z_cap: f32,
    /// A point light: its position (baker units).
    pub pos: [f32; 3],
    /// 1 for a point light at `pos`, 0 for a distant light along `dir`.
    pub point: u32,
    /// Texels in the band.
    pub texels: u32,
    /// Footprint samples per texel.
    pub spp: u32,
    /// Where the light's counts start in the counts buffer.
    pub out_offset: u32,
    /// The light's slot in the pass.
    pub slot: u32,
}

/// `Sample` in trace.wgsl: a footprint sample's shadow-ray origin and unit normal.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Sample {
    /// Shadow-ray origin (baker units).
    pub org: [f32; 3],
    /// 1 where the primary ray hit, else 0.
    pub covered: u32,
    /// Unit normal face-forwarded towards the camera.
    pub n: [f32; 3],
    /// Padding to 32 bytes.
    pub _pad: u32,
}

/// The GPU's tracer of one bake: device, acceleration structures, and the primary samples of
/// every band (on the device when there is one band, else on the host between passes).
pub struct GpuBaker {
    gpu: Gpu,
    cfg: BakeConfig,
    tile: [f64; 2],
    bounds: ptm_bake::swatch::Bounds,
    /// Point-light distance in the baker's units.
    light_distance: Option<f64>,
    z_cap: f64,
    margin: f64,
    scene: Scene,
    rows: Range<usize>,
    bands: Vec<Range<usize>>,
    per_pass: usize,
    /// Per band, its samples (sample-major: sample s of texel t at s × texels + t), when there
    /// are several bands.
    host_samples: Vec<Vec<Sample>>,
    /// The band's samples on the device (sized for the largest band).
    samples: wgpu::Buffer,
    /// Per traced texel, the samples whose primary ray hit.
    covered: Vec<u32>,
    coverage: Vec<f32>,
    surface: Option<Surface>,
    shadow: wgpu::ComputePipeline,
    /// The host's threads (`BakeConfig::threads`; 0: one per core).
    pool: rayon::ThreadPool,
    report: BakeReport,
}

/// A light above the horizon: as traced, and the copies its TLAS holds.
type Plan = (Light, Vec<[i32; 2]>);

/// A light as the shader traces it.
#[derive(Clone, Copy)]
enum Light {
    /// Unit direction towards a distant light, in f32.
    Distant([f32; 3]),
    /// Position of a point light (baker units).
    Point([f64; 3]),
}

/// Workgroups (x, y) covering `n` invocations of 64, x at most 65,535.
fn groups(n: u32) -> (u32, u32) {
    let g = n.div_ceil(64).max(1);
    let x = g.min(65_535);
    (x, g.div_ceil(x))
}

impl GpuBaker {
    /// Opens a device with ray queries on `adapter`, checks the mesh and the bands against its
    /// limits (before any upload), builds the BLAS and traces the primary hits of image rows
    /// `rows` (a farm shard's block, or all), band by band. `surface`: also sum the primary
    /// hits per texel for the companion maps ([`Tracer::take_surface`]).
    pub fn new_rows(
        adapter: &wgpu::Adapter,
        swatch: &PreparedMesh,
        cfg: &BakeConfig,
        rows: Range<usize>,
        gpu_cfg: &GpuConfig,
        surface: bool,
    ) -> Result<GpuBaker> {
        ptm_bake::check_config(swatch, cfg, &rows)?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(cfg.threads)
            .build()
            .map_err(|e| ptm_bake::Error::Config(format!("thread pool: {e}")))?;
        let gpu = Gpu::open(adapter)?;
        let frame = Frame::new(swatch);
        let mesh = &*frame.swatch;
        // Everything is checked before anything is uploaded.
        Scene::check(
            &gpu.limits,
            &gpu.name,
            mesh.positions.len(),
            mesh.triangles.len(),
        )?;
        let width = cfg.res[0];
        let point = cfg.light_distance.is_some();
        let per_pass = budget::lights_per_pass(width, rows.len(), point);
        let shape = budget::Rows {
            width,
            spp: cfg.spp,
            per_pass,
            point,
        };
        let bands = budget::bands(
            &gpu.limits,
            &gpu.name,
            gpu_cfg.band_bytes,
            rows.clone(),
            &shape,
        )?;
        let t0 = Instant::now();
        let mut scene = Scene::new(&gpu, &mesh.positions, &mesh.triangles, mesh.tile)?;
        let primary_copies = tiling::copies_meeting(mesh.tile, &mesh.bounds, &[], frame.margin);
        scene.prepare(&gpu, &primary_copies)?;
        gpu.wait("building the tile copies' TLAS")?;
        let seconds_scene = t0.elapsed().as_secs_f64();
        let module = gpu
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("trace.wgsl"),
                source: wgpu::ShaderSource::Wgsl(SHADER.into()),
            });
        let pipeline = |entry: &str| {
            gpu.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: None,
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
        };
        let primary = pipeline("primary");
        let shadow = pipeline("shadow");
        gpu.wait("compiling the shaders")?;
        let largest = bands.iter().map(|b| b.len()).max().unwrap_or(0);
        let band_samples = (largest * width * cfg.spp as usize) as u64;
        let samples = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("shadow samples"),
            size: (band_samples * 32).max(32),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut baker = GpuBaker {
            cfg: cfg.clone(),
            tile: mesh.tile,
            bounds: mesh.bounds,
            light_distance: cfg.light_distance.map(|r| r * frame.unit),
            z_cap: frame.z_cap,
            margin: frame.margin,
            scene,
            rows: rows.clone(),
            per_pass,
            host_samples: Vec::new(),
            samples,
            covered: Vec::with_capacity(width * rows.len()),
            coverage: Vec::with_capacity(width * rows.len()),
            surface: surface.then(|| Surface::new(width, 0, cfg.spp as usize)),
            shadow,
            pool,
            report: BakeReport {
                seconds_scene,
                ..Default::default()
            },
            bands: bands.clone(),
            gpu,
        };
        let t1 = Instant::now();
        let tlas = baker.scene.tlas(&primary_copies).clone();
        for band in &bands {
            baker.primary(&primary, &tlas, &frame, band.clone())?;
        }
        baker.report.seconds_primary = t1.elapsed().as_secs_f64();
        baker.report.primary_rays = (width * rows.len()) as u64 * cfg.spp as u64;
        baker.report.uncovered_texels = baker.covered.iter().filter(|&&c| c == 0).count();
        Ok(baker)
    }

    /// The adapter, described.
    pub fn adapter(&self) -> &str {
        &self.gpu.name
    }

    /// The device (tests use it to lose the device mid-bake).
    pub fn device(&self) -> &wgpu::Device {
        &self.gpu.device
    }

    /// The bands of image rows traced, in order.
    pub fn bands(&self) -> &[Range<usize>] {
        &self.bands
    }

    /// Lights traced per pass over the bands.
    pub fn lights_per_pass(&self) -> usize {
        self.per_pass
    }

    /// Primary pass over one band: sample positions from the CPU bake's hash, one ray each on
    /// the device, the hits read back and turned into shadow samples exactly as the CPU bake
    /// does ([`Frame::primary_sample`]), with the band's coverage and surface sums.
    fn primary(
        &mut self,
        pipeline: &wgpu::ComputePipeline,
        tlas: &wgpu::Tlas,
        frame: &Frame,
        band: Range<usize>,
    ) -> Result<()> {
        let (nx, spp) = (self.cfg.res[0], self.cfg.spp as usize);
        let (res, tile, seed) = (self.cfg.res, self.tile, self.cfg.seed);
        // Texel-major (row, column, sample), hashed in parallel: each is its own hash.
        let xy64: Vec<[f64; 2]> = self.pool.install(|| {
            (0..band.len() * nx * spp)
                .into_par_iter()
                .map(|k| {
                    let (t, s) = (k / spp, k % spp);
                    let texel = [t % nx, band.start + t / nx];
                    ptm_bake::sample_xy(res, tile, spp, seed, texel, s)
                })
                .collect()
        });
        let xy: Vec<[f32; 2]> = xy64.iter().map(|p| p.map(|c| c as f32)).collect();
        let count = xy.len() as u32;
        let d = &self.gpu.device;
        let params = PrimaryParams {
            z_top: self.z_cap as f32,
            // Below the lowest geometry by far: the camera is at most a tile size above it.
            t_max: (self.z_cap - self.bounds.min[2]) as f32 * 2.0 + 1.0,
            count,
            _pad: 0,
        };
        let uniform = d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("primary params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let xy_buf = d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("sample positions"),
            contents: bytemuck::cast_slice(&xy),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let hits_buf = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("primary hits"),
            size: count as u64 * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let bind = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("primary"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: tlas.as_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: uniform.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: xy_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: hits_buf.as_entire_binding(),
                },
            ],
        });
        let mut enc = d.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind, &[]);
            let (gx, gy) = groups(count);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        self.gpu.queue.submit([enc.finish()]);
        let hits: Vec<Hit> = self
            .gpu
            .read(&hits_buf, count as u64 * 8, "tracing primary rays")?;
        // Each hit's shadow sample, in parallel (the CPU bake's own maths, per sample); then
        // coverage and surface sums texel by texel, samples in order.
        let mesh = &*frame.swatch;
        let found: Vec<Option<ptm_bake::PrimarySample>> = self.pool.install(|| {
            hits.par_iter()
                .zip(xy64.par_iter())
                .map(|(h, &xy)| {
                    let tri = mesh.triangles.get(h.prim as usize);
                    let tri = tri.filter(|_| h.prim != NO_HIT)?;
                    frame.primary_sample(xy, h.t, geometric_normal(mesh, *tri))
                })
                .collect()
        });
        let mut samples = vec![Sample::default(); hits.len()];
        let mut surface = self
            .surface
            .as_ref()
            .map(|_| Surface::new(nx, band.len(), spp));
        let texels = band.len() * nx;
        for t in 0..texels {
            let mut covered = 0u32;
            for s in 0..spp {
                // Hits are texel-major; shadow samples sample-major (trace.wgsl's layout).
                let k = t * spp + s;
                let Some(ps) = found[k] else {
                    continue;
                };
                samples[s * texels + t] = Sample {
                    org: ps.org,
                    covered: 1,
                    n: ps.n32,
                    _pad: 0,
                };
                covered += 1;
                if let Some(sf) = surface.as_mut() {
                    let prim = hits[k].prim;
                    let hit = SurfaceHit {
                        z: ps.p[2] * (1.0 / frame.unit),
                        n: ps.n,
                        prim,
                    };
                    let m = mesh.materials.get(prim as usize).copied();
                    sf.add(t, s, &hit, m.unwrap_or(0));
                }
            }
            self.covered.push(covered);
            self.coverage.push(covered as f32 / spp as f32);
        }
        if let (Some(all), Some(band)) = (self.surface.as_mut(), surface) {
            all.append_rows(band);
        }
        if self.bands.len() == 1 {
            self.gpu
                .queue
                .write_buffer(&self.samples, 0, bytemuck::cast_slice(&samples));
        } else {
            self.host_samples.push(samples);
        }
        Ok(())
    }

    fn trace_gpu(&mut self, lights: &LightSet, sink: &mut Sink) -> Result<BakeReport> {
        let t0 = Instant::now();
        let nx = self.cfg.res[0];
        let n_rows = self.rows.len();
        let spp = self.cfg.spp;
        let mut rep = BakeReport {
            primary_rays: self.report.primary_rays,
            uncovered_texels: self.report.uncovered_texels,
            seconds_scene: self.report.seconds_scene,
            seconds_primary: self.report.seconds_primary,
            ..Default::default()
        };
        // Plan every light and build its TLAS first, as the CPU bake builds its scenes.
        let mut plans: Vec<Option<Plan>> = Vec::with_capacity(lights.len());
        for (li, &l) in lights.dirs.iter().enumerate() {
            if l[2] <= 0.0 {
                rep.rings.push(0);
                rep.copies.push(0);
                rep.below_horizon.push(li);
                plans.push(None);
                continue;
            }
            let (light, copies) = match self.light_distance {
                None => (
                    Light::Distant(l.map(|c| c as f32)),
                    tiling::copies_for_direction(self.tile, &self.bounds, l, self.margin),
                ),
                Some(r) => {
                    let centre = [self.tile[0] / 2.0, self.tile[1] / 2.0, 0.0];
                    let p = [0, 1, 2].map(|a| centre[a] + r * l[a]);
                    let copies = tiling::copies_for_point(self.tile, &self.bounds, p, self.margin);
                    (Light::Point(p), copies)
                }
            };
            if tiling::run_is_capped(self.tile, &self.bounds, l) {
                rep.capped.push(li);
            }
            rep.rings.push(tiling::rings(&copies));
            rep.copies.push(copies.len());
            self.scene.prepare(&self.gpu, &copies)?;
            plans.push(Some((light, copies)));
        }
        self.gpu.wait("building the lights' TLASes")?;
        rep.seconds_scene += t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let d = self.gpu.device.clone();
        let per_pass = self.per_pass.min(lights.len()).max(1);
        let largest = self.bands.iter().map(|b| b.len()).max().unwrap_or(0) * nx;
        // Each light's params at its own offset: the struct's size rounded up to the device's
        // uniform offset alignment.
        let align = (std::mem::size_of::<ShadowParams>() as u64)
            .next_multiple_of(self.gpu.limits.min_uniform_buffer_offset_alignment as u64);
        let params_buf = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("shadow params"),
            size: align * per_pass as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let counts_bytes = (per_pass * largest) as u64 * 4;
        let counts = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("occluded counts"),
            size: counts_bytes.max(4),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        // (u, v) per slot and texel for point lights; a token buffer otherwise (never written).
        let point = self.light_distance.is_some();
        let uv_bytes = if point {
            (per_pass * largest) as u64 * 8
        } else {
            0
        };
        let uv = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("mean directions"),
            size: uv_bytes.max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let traced = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("traced rays"),
            size: per_pass as u64 * 4,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = self.shadow.get_bind_group_layout(0);
        let mut k_planes = vec![vec![0.0f32; nx * n_rows]; per_pass];
        let mut uv_planes = vec![vec![[0.0f32; 2]; if point { nx * n_rows } else { 0 }]; per_pass];
        for (p, pass) in plans.chunks(per_pass).enumerate() {
            // One bind group per light of the pass: its TLAS and its slot of the params.
            let binds: Vec<Option<wgpu::BindGroup>> = pass
                .iter()
                .enumerate()
                .map(|(slot, plan)| {
                    let (_, copies) = plan.as_ref()?;
                    Some(d.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("shadow"),
                        layout: &layout,
                        entries: &[
                            wgpu::BindGroupEntry {
                                binding: 0,
                                resource: self.scene.tlas(copies).as_binding(),
                            },
                            wgpu::BindGroupEntry {
                                binding: 4,
                                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                    buffer: &params_buf,
                                    offset: slot as u64 * align,
                                    size: wgpu::BufferSize::new(
                                        std::mem::size_of::<ShadowParams>() as u64,
                                    ),
                                }),
                            },
                            wgpu::BindGroupEntry {
                                binding: 5,
                                resource: self.samples.as_entire_binding(),
                            },
                            wgpu::BindGroupEntry {
                                binding: 6,
                                resource: counts.as_entire_binding(),
                            },
                            wgpu::BindGroupEntry {
                                binding: 7,
                                resource: traced.as_entire_binding(),
                            },
                            wgpu::BindGroupEntry {
                                binding: 8,
                                resource: uv.as_entire_binding(),
                            },
                        ],
                    }))
                })
                .collect();
            for (b, band) in self.bands.iter().enumerate() {
                let texels = band.len() * nx;
                let local = (band.start - self.rows.start) * nx;
                if let Some(s) = self.host_samples.get(b) {
                    self.gpu
                        .queue
                        .write_buffer(&self.samples, 0, bytemuck::cast_slice(s));
                }
                for (slot, plan) in pass.iter().enumerate() {
                    let (dir, pos, point) = match plan.as_ref().map(|p| p.0) {
                        Some(Light::Distant(l)) => (l, [0.0; 3], 0),
                        Some(Light::Point(p)) => ([0.0; 3], p.map(|c| c as f32), 1),
                        None => ([0.0; 3], [0.0; 3], 0),
                    };
                    let params = ShadowParams {
                        dir,
                        z_cap: self.z_cap as f32,
                        pos,
                        point,
                        texels: texels as u32,
                        spp,
                        out_offset: (slot * largest) as u32,
                        slot: slot as u32,
                    };
                    self.gpu.queue.write_buffer(
                        &params_buf,
                        slot as u64 * align,
                        bytemuck::bytes_of(&params),
                    );
                }
                self.gpu
                    .queue
                    .write_buffer(&traced, 0, &vec![0u8; per_pass * 4]);
                let mut enc = d.create_command_encoder(&Default::default());
                {
                    let mut cp = enc.begin_compute_pass(&Default::default());
                    cp.set_pipeline(&self.shadow);
                    let (gx, gy) = groups(texels as u32);
                    for bind in binds.iter().flatten() {
                        cp.set_bind_group(0, bind, &[]);
                        cp.dispatch_workgroups(gx, gy, 1);
                    }
                }
                self.gpu.queue.submit([enc.finish()]);
                let occ: Vec<u32> = self
                    .gpu
                    .read(&counts, counts_bytes, "tracing shadow rays")?;
                let uvs: Vec<[f32; 2]> = if point {
                    self.gpu.read(&uv, uv_bytes, "tracing shadow rays")?
                } else {
                    Vec::new()
                };
                let rays: Vec<u32> =
                    self.gpu
                        .read(&traced, per_pass as u64 * 4, "tracing shadow rays")?;
                for (slot, plan) in pass.iter().enumerate() {
                    let k = &mut k_planes[slot][local..local + texels];
                    let cov = &self.covered[local..local + texels];
                    let covered: u64 = cov.iter().map(|&c| c as u64).sum();
                    match plan {
                        // Below the horizon: occluded wherever covered, no ray.
                        None => {
                            for (k, &c) in k.iter_mut().zip(cov) {
                                *k = if c > 0 { 1.0 } else { 0.0 };
                            }
                            rep.shadow_rays_skipped += covered;
                        }
                        Some(_) => {
                            let o = &occ[slot * largest..slot * largest + texels];
                            for ((k, &c), &o) in k.iter_mut().zip(cov).zip(o) {
                                *k = if c > 0 { o as f32 / c as f32 } else { 0.0 };
                            }
                            if point {
                                uv_planes[slot][local..local + texels]
                                    .copy_from_slice(&uvs[slot * largest..slot * largest + texels]);
                            }
                            rep.shadow_rays += rays[slot] as u64;
                            rep.shadow_rays_skipped += covered - rays[slot] as u64;
                        }
                    }
                }
            }
            for (slot, (k, plan)) in k_planes.iter().zip(pass).enumerate() {
                // As the CPU bake: (u, v) planes for point lights above the horizon.
                let uv = matches!(plan, Some((Light::Point(_), _))).then_some(&uv_planes[slot][..]);
                sink(p * per_pass + slot, k, uv)?;
            }
        }
        rep.seconds_shadow = t1.elapsed().as_secs_f64();
        Ok(rep)
    }
}

/// The triangle's geometric normal in f32, as Embree forms it (any length, either side: the
/// primary sample normalises and face-forwards it).
fn geometric_normal(mesh: &PreparedMesh, t: [u32; 3]) -> [f32; 3] {
    let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
    let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ]
}

impl Tracer for GpuBaker {
    fn rows(&self) -> Range<usize> {
        self.rows.clone()
    }
    fn coverage(&self) -> &[f32] {
        &self.coverage
    }
    fn take_surface(&mut self) -> Option<Surface> {
        self.surface.take()
    }
    fn trace(&mut self, lights: &LightSet, sink: &mut Sink) -> ptm_bake::Result<BakeReport> {
        Ok(self.trace_gpu(lights, sink)?)
    }
}

/// Bakes `lights` over `swatch` on `adapter` into memory: (planes, coverage, report), as
/// `ptm_bake::bake_planes` does on the CPU.
pub fn bake_planes(
    adapter: &wgpu::Adapter,
    swatch: &PreparedMesh,
    lights: &LightSet,
    cfg: &BakeConfig,
    gpu_cfg: &GpuConfig,
) -> Result<(ptm_bake::Planes, Vec<f32>, BakeReport)> {
    let mut baker = GpuBaker::new_rows(adapter, swatch, cfg, 0..cfg.res[1], gpu_cfg, false)?;
    let mut planes = ptm_bake::Planes::default();
    let report = baker.trace_gpu(lights, &mut |i, k, uv| planes.push(i, k, uv))?;
    Ok((planes, baker.coverage.clone(), report))
}
