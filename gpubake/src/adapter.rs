//! Which device bakes: `cpu`, `gpu` or `auto`, and why. `auto` takes a GPU whose adapter has
//! hardware ray queries and is not a CPU device (lavapipe's software ray queries are no faster
//! than Embree on the same cores), otherwise the CPU; the choice, the adapter and the reason
//! are values the command prints (`--json`, stderr).
use std::sync::{Arc, Mutex};

use crate::{Error, Result};

/// The device the user asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Asked {
    /// Embree on the CPU.
    Cpu,
    /// A GPU adapter with ray queries (a CPU device such as lavapipe included: for testing).
    Gpu,
    /// A hardware GPU with ray queries if there is one, else the CPU.
    Auto,
}

impl Asked {
    /// Every value, in the order the command line lists them.
    pub const ALL: [Asked; 3] = [Asked::Cpu, Asked::Gpu, Asked::Auto];

    /// The command line's name of this value.
    pub fn name(self) -> &'static str {
        match self {
            Asked::Cpu => "cpu",
            Asked::Gpu => "gpu",
            Asked::Auto => "auto",
        }
    }
}

/// The device that bakes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Used {
    /// Embree on the CPU.
    Cpu,
    /// wgpu ray queries on the chosen adapter.
    Gpu,
}

impl Used {
    /// `cpu` or `gpu`.
    pub fn name(self) -> &'static str {
        match self {
            Used::Cpu => "cpu",
            Used::Gpu => "gpu",
        }
    }
}

/// What [`choose`] decided.
#[derive(Debug)]
pub struct Choice {
    /// What was asked for.
    pub asked: Asked,
    /// What bakes.
    pub used: Used,
    /// The adapter that bakes (with [`Used::Gpu`]).
    pub adapter: Option<wgpu::Adapter>,
    /// The adapter that bakes, or for `auto` on the CPU the best adapter seen, described.
    pub adapter_name: Option<String>,
    /// Why, in words.
    pub reason: String,
}

/// "name (backend, device type, driver)".
pub fn describe(info: &wgpu::AdapterInfo) -> String {
    let driver = [info.driver.as_str(), info.driver_info.as_str()]
        .iter()
        .filter(|s| !s.is_empty())
        .copied()
        .collect::<Vec<_>>()
        .join(" ");
    if driver.is_empty() {
        format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
    } else {
        format!(
            "{} ({:?}, {:?}, {driver})",
            info.name, info.backend, info.device_type
        )
    }
}

/// Whether `adapter` can open a device with ray queries.
pub fn has_ray_queries(adapter: &wgpu::Adapter) -> bool {
    adapter
        .features()
        .contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY)
}

/// Preference among adapters with ray queries: discrete, integrated, virtual, other, CPU.
fn rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

/// Every adapter of the native backends (`WGPU_BACKEND` narrows them).
pub fn adapters() -> Vec<wgpu::Adapter> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
    pollster::block_on(instance.enumerate_adapters(backends))
}

/// Decides which device bakes. An error only for [`Asked::Gpu`] with no adapter that has ray
/// queries (naming every adapter found).
pub fn choose(asked: Asked) -> Result<Choice> {
    if asked == Asked::Cpu {
        return Ok(Choice {
            asked,
            used: Used::Cpu,
            adapter: None,
            adapter_name: None,
            reason: "asked for the CPU".into(),
        });
    }
    choose_from(asked, adapters())
}

/// [`choose`] among `adapters` (for [`Asked::Gpu`] or [`Asked::Auto`]). `WGPU_ADAPTER_NAME`,
/// when set, keeps only adapters whose name contains it (ignoring case).
pub fn choose_from(asked: Asked, adapters: Vec<wgpu::Adapter>) -> Result<Choice> {
    let mut found: Vec<String> = adapters.iter().map(|a| describe(&a.get_info())).collect();
    let named = std::env::var("WGPU_ADAPTER_NAME").ok();
    let wanted = |a: &wgpu::Adapter| {
        named
            .as_ref()
            .is_none_or(|n| a.get_info().name.to_lowercase().contains(&n.to_lowercase()))
    };
    let mut rq: Vec<wgpu::Adapter> = adapters
        .into_iter()
        .filter(|a| has_ray_queries(a) && wanted(a))
        .collect();
    if let Some(n) = &named {
        found.push(format!(
            "WGPU_ADAPTER_NAME={n:?} keeps only adapters of that name"
        ));
    }
    rq.sort_by_key(|a| rank(a.get_info().device_type));
    let hardware = rq
        .iter()
        .position(|a| a.get_info().device_type != wgpu::DeviceType::Cpu);
    let pick = match asked {
        Asked::Gpu => rq.first().map(|_| 0),
        _ => hardware,
    };
    if let Some(i) = pick {
        let adapter = rq.swap_remove(i);
        let name = describe(&adapter.get_info());
        let reason = match (asked, adapter.get_info().device_type) {
            (Asked::Gpu, wgpu::DeviceType::Cpu) => {
                format!("asked for the GPU: {name} has ray queries, in software on the CPU")
            }
            (Asked::Gpu, _) => format!("asked for the GPU: {name} has hardware ray queries"),
            _ => format!("{name} has hardware ray queries"),
        };
        return Ok(Choice {
            asked,
            used: Used::Gpu,
            adapter: Some(adapter),
            adapter_name: Some(name),
            reason,
        });
    }
    if asked == Asked::Gpu {
        return Err(Error::NoRayQueries { found });
    }
    let seen = found.first().cloned();
    let reason = match rq.first() {
        Some(a) => format!(
            "the only adapter with ray queries, {}, is a CPU device (software ray queries on the \
             cores Embree uses)",
            describe(&a.get_info())
        ),
        None if found.is_empty() => "wgpu found no GPU adapter".to_string(),
        None => format!("no adapter has ray queries (found: {})", found.join("; ")),
    };
    Ok(Choice {
        asked,
        used: Used::Cpu,
        adapter: None,
        adapter_name: seen,
        reason,
    })
}

/// A device with ray queries on one adapter, and the first error wgpu reported on it (lost
/// device, out of memory, validation), which the baker checks after every wait.
#[derive(Clone)]
pub struct Gpu {
    /// The wgpu device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter, described.
    pub name: String,
    /// The adapter's limits, which the device was opened with.
    pub limits: wgpu::Limits,
    failure: Arc<Mutex<Option<String>>>,
}

impl Gpu {
    /// Opens a device on `adapter` with `EXPERIMENTAL_RAY_QUERY` and the adapter's own limits
    /// (wgpu's "minimum supported acceleration structure" limits ask for 2²⁸ BLAS primitives;
    /// lavapipe allows 16,777,215).
    pub fn open(adapter: &wgpu::Adapter) -> Result<Gpu> {
        let name = describe(&adapter.get_info());
        if !has_ray_queries(adapter) {
            return Err(Error::NoRayQueries { found: vec![name] });
        }
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("ptm-gpubake"),
            required_features: wgpu::Features::EXPERIMENTAL_RAY_QUERY,
            required_limits: limits.clone(),
            // SAFETY (wgpu's contract for experimental features): ray queries are used only as
            // documented; the shaders are validated by naga and tested against the CPU bake.
            experimental_features: unsafe { wgpu::ExperimentalFeatures::enabled() },
            ..Default::default()
        }))
        .map_err(|e| Error::Device {
            adapter: name.clone(),
            reason: e.to_string(),
        })?;
        let failure = Arc::new(Mutex::new(None::<String>));
        let slot = failure.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut f) = slot.lock() {
                f.get_or_insert_with(|| e.to_string());
            }
        }));
        let slot = failure.clone();
        device.set_device_lost_callback(move |reason, msg| {
            if let Ok(mut f) = slot.lock() {
                f.get_or_insert_with(|| format!("device lost ({reason:?}): {msg}"));
            }
        });
        Ok(Gpu {
            device,
            queue,
            name,
            limits,
            failure,
        })
    }

    /// Waits for the queue; an error if the device failed at any point so far.
    pub fn wait(&self, stage: &'static str) -> Result<()> {
        let polled = self.device.poll(wgpu::PollType::wait_indefinitely());
        if let Some(reason) = self.failure.lock().ok().and_then(|f| f.clone()) {
            return Err(self.lost(stage, reason));
        }
        polled
            .map(|_| ())
            .map_err(|e| self.lost(stage, e.to_string()))
    }

    /// Error [`Error::Lost`] at `stage`.
    pub fn lost(&self, stage: &'static str, reason: String) -> Error {
        Error::Lost {
            stage,
            adapter: self.name.clone(),
            reason,
        }
    }

    /// Copies the first `bytes` of `buffer` (a `COPY_SRC` buffer) back.
    pub fn read<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        bytes: u64,
        stage: &'static str,
    ) -> Result<Vec<T>> {
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes);
        self.queue.submit([enc.finish()]);
        let slice = staging.slice(..bytes);
        let mapped = Arc::new(Mutex::new(None));
        let m = mapped.clone();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            if let Ok(mut m) = m.lock() {
                *m = Some(r);
            }
        });
        self.wait(stage)?;
        match mapped.lock().ok().and_then(|mut m| m.take()) {
            Some(Ok(())) => {}
            Some(Err(e)) => return Err(self.lost(stage, e.to_string())),
            None => return Err(self.lost(stage, "the readback never completed".into())),
        }
        let data = slice
            .get_mapped_range()
            .map_err(|e| self.lost(stage, e.to_string()))?;
        let out = bytemuck::pod_collect_to_vec(&data);
        drop(data);
        staging.unmap();
        Ok(out)
    }
}
