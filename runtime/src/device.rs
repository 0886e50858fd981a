//! The headless device: adapter and device creation, storage buffers, compute dispatch and
//! readback, shared by the shading pass ([`crate::gpu`]) and the blur methods' passes
//! ([`crate::blur`]).
//!
//! Timings are wall-clock seconds around each submission plus a blocking wait, so they include
//! submission overhead; on lavapipe the "GPU" is the CPU.

use wgpu::util::DeviceExt;

use crate::{Error, Result};

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

    pub(crate) fn wait(&self, stage: &'static str) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| Error::Gpu {
                stage,
                reason: e.to_string(),
            })
    }

    pub(crate) fn storage(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        self.storage_with(label, bytes, wgpu::BufferUsages::empty())
    }

    /// A storage buffer with further `usage` (e.g. `COPY_DST` to rewrite it).
    pub(crate) fn storage_with(
        &self,
        label: &str,
        bytes: &[u8],
        usage: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
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

impl Gpu {
    /// A storage buffer that can also be copied from (inputs to compute passes, tests).
    pub(crate) fn storage_copyable(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
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

    /// Records one compute pass of `entry` in `module` over `threads` invocations (64 per
    /// workgroup, at least one workgroup) with storage/uniform `bindings` of group 0, whose
    /// layout wgpu derives from what the entry point uses.
    pub(crate) fn dispatch(
        &self,
        enc: &mut wgpu::CommandEncoder,
        module: &wgpu::ShaderModule,
        entry: &str,
        bindings: &[(u32, &wgpu::Buffer)],
        threads: u32,
    ) {
        let pipeline = self
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
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(entry),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(threads.div_ceil(64).max(1), 1, 1);
    }

    /// Copies the first `bytes` of a `COPY_SRC` buffer back (for tests and benchmarks).
    pub(crate) fn read_buffer<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        bytes: u64,
    ) -> Result<Vec<T>> {
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes);
        self.queue.submit([enc.finish()]);
        Ok(bytemuck::pod_collect_to_vec(&map_read(self, &staging)?))
    }
}

pub(crate) fn map_read(gpu: &Gpu, staging: &wgpu::Buffer) -> Result<Vec<u8>> {
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
