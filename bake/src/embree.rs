//! A small safe wrapper over `embree4-sys`: device, triangle and instance geometry, committed
//! scenes, and the three queries the baker needs (`rtcIntersect1`, `rtcOccluded1`,
//! `rtcOccluded16`), plus FTZ/DAZ for tracing threads.
//!
//! Hazards handled here (see `/work/shared/notes/bake.md`): the config string passed to
//! `rtcNewDevice` is NUL-terminated; `rtcIntersect1` gets a 96-byte padded `RTCRayHit` because
//! Embree 4.4 built with instance arrays writes `instPrimID` past the 80-byte struct of the 4.2
//! headers; errors arrive through a device callback instead of a `rtcGetDeviceError` per ray.
use std::ffi::{c_char, c_void, CStr, CString};
use std::ptr;
use std::sync::Mutex;

use embree4_sys as sys;

use crate::{Error, Result};

/// Errors reported by Embree's callback since the last [`Device::take_error`].
struct ErrorSlot(Mutex<Option<String>>);

unsafe extern "C" fn on_error(user: *mut c_void, code: sys::RTCError, msg: *const c_char) {
    // SAFETY: `user` is the `ErrorSlot` owned by the `Device` that registered this callback;
    // it lives until the device is released.
    let slot = unsafe { &*(user as *const ErrorSlot) };
    let text = if msg.is_null() {
        String::new()
    } else {
        // SAFETY: Embree passes a NUL-terminated message.
        unsafe { CStr::from_ptr(msg) }
            .to_string_lossy()
            .into_owned()
    };
    if let Ok(mut e) = slot.0.lock() {
        e.get_or_insert_with(|| format!("{code:?}: {text}"));
    }
}

/// An Embree device (owns Embree's thread pool and error state).
pub struct Device {
    raw: sys::RTCDevice,
    errors: Box<ErrorSlot>,
}

// SAFETY: Embree devices are thread-safe; the error slot is behind a mutex.
unsafe impl Send for Device {}
unsafe impl Sync for Device {}

impl Device {
    /// A device with an Embree config string such as `"threads=2"` (may be empty).
    pub fn new(config: &str) -> Result<Self> {
        let cfg = CString::new(config)
            .map_err(|_| Error::Embree(format!("device config {config:?} contains NUL")))?;
        // SAFETY: `cfg` is NUL-terminated and outlives the call.
        let raw = unsafe { sys::rtcNewDevice(cfg.as_ptr()) };
        if raw.is_null() {
            // SAFETY: a null device is allowed here and yields the creation error.
            let code = unsafe { sys::rtcGetDeviceError(ptr::null_mut()) };
            return Err(Error::Embree(format!(
                "rtcNewDevice({config:?}) failed: {code:?}; is libembree4 4.x installed (scripts/setup.sh)?"
            )));
        }
        let errors = Box::new(ErrorSlot(Mutex::new(None)));
        // SAFETY: the callback's user pointer is the boxed slot, kept alive by `self`.
        unsafe {
            sys::rtcSetDeviceErrorFunction(
                raw,
                Some(on_error),
                &*errors as *const ErrorSlot as *mut c_void,
            )
        };
        Ok(Self { raw, errors })
    }

    /// Embree's version as `major * 10000 + minor * 100 + patch` (40400 for 4.4.0).
    pub fn version(&self) -> isize {
        // SAFETY: valid device.
        unsafe { sys::rtcGetDeviceProperty(self.raw, sys::RTCDeviceProperty::VERSION) }
    }

    /// The first error Embree reported since the last call, as an `Err`.
    pub fn take_error(&self, context: &str) -> Result<()> {
        match self.errors.0.lock().ok().and_then(|mut e| e.take()) {
            Some(msg) => Err(Error::Embree(format!("{context}: {msg}"))),
            None => Ok(()),
        }
    }

    /// A scene of triangles (`positions` xyz, `triangles` vertex indices), built with medium
    /// quality and committed. HIGH (spatial splits, meant for long thin triangles such as yarn
    /// segments) cost 0.07–0.1 CPU-s more on the 110k-triangle weave and traced no faster at
    /// 2,400 rays per triangle (bench_shards: 7.26–7.46 against 7.36–7.86 CPU-s of tracing),
    /// while every farm shard pays the build again. Every bake, whole or sharded, uses this
    /// one quality, so the shards' hits are the whole bake's.
    pub fn triangle_scene(&self, positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Result<Scene> {
        // SAFETY: every handle is checked for null; buffers are sized by Embree for exactly
        // the counts we write (Embree pads vertex buffers for its 16-byte loads itself).
        unsafe {
            let geom = sys::rtcNewGeometry(self.raw, sys::RTCGeometryType::TRIANGLE);
            if geom.is_null() {
                self.take_error("rtcNewGeometry")?;
                return Err(Error::Embree("rtcNewGeometry returned null".into()));
            }
            let vb = sys::rtcSetNewGeometryBuffer(
                geom,
                sys::RTCBufferType::VERTEX,
                0,
                sys::RTCFormat::FLOAT3,
                12,
                positions.len(),
            ) as *mut [f32; 3];
            let ib = sys::rtcSetNewGeometryBuffer(
                geom,
                sys::RTCBufferType::INDEX,
                0,
                sys::RTCFormat::UINT3,
                12,
                triangles.len(),
            ) as *mut [u32; 3];
            if vb.is_null() || ib.is_null() {
                sys::rtcReleaseGeometry(geom);
                self.take_error("rtcSetNewGeometryBuffer")?;
                return Err(Error::Embree("geometry buffer allocation failed".into()));
            }
            ptr::copy_nonoverlapping(positions.as_ptr(), vb, positions.len());
            ptr::copy_nonoverlapping(triangles.as_ptr(), ib, triangles.len());
            sys::rtcCommitGeometry(geom);
            let scene = self.new_scene(sys::RTCBuildQuality::MEDIUM)?;
            sys::rtcAttachGeometry(scene.raw, geom);
            sys::rtcReleaseGeometry(geom);
            scene.commit(self)
        }
    }

    /// A scene of translated instances of `child` (one per offset), committed.
    pub fn instance_scene(&self, child: &Scene, offsets: &[[f32; 3]]) -> Result<Scene> {
        let scene = self.new_scene(sys::RTCBuildQuality::MEDIUM)?;
        for o in offsets {
            // Column-major 3×4 affine transform: identity rotation, translation `o`.
            let xfm: [f32; 12] = [
                1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, o[0], o[1], o[2],
            ];
            // SAFETY: valid handles; the transform is copied by Embree.
            unsafe {
                let geom = sys::rtcNewGeometry(self.raw, sys::RTCGeometryType::INSTANCE);
                if geom.is_null() {
                    self.take_error("rtcNewGeometry(INSTANCE)")?;
                    return Err(Error::Embree("rtcNewGeometry returned null".into()));
                }
                sys::rtcSetGeometryInstancedScene(geom, child.raw);
                sys::rtcSetGeometryTransform(
                    geom,
                    0,
                    sys::RTCFormat::FLOAT3X4_COLUMN_MAJOR,
                    xfm.as_ptr() as *const c_void,
                );
                sys::rtcCommitGeometry(geom);
                sys::rtcAttachGeometry(scene.raw, geom);
                sys::rtcReleaseGeometry(geom);
            }
        }
        scene.commit(self)
    }

    fn new_scene(&self, quality: sys::RTCBuildQuality) -> Result<UncommittedScene> {
        // SAFETY: valid device.
        let raw = unsafe { sys::rtcNewScene(self.raw) };
        if raw.is_null() {
            self.take_error("rtcNewScene")?;
            return Err(Error::Embree("rtcNewScene returned null".into()));
        }
        // SAFETY: valid scene.
        unsafe { sys::rtcSetSceneBuildQuality(raw, quality) };
        Ok(UncommittedScene { raw })
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: scenes hold their own reference to the device, so releasing ours is safe
        // even while scenes are alive. The callback is removed first because its user pointer
        // (the error slot) is freed with `self`.
        unsafe {
            sys::rtcSetDeviceErrorFunction(self.raw, None, ptr::null_mut());
            sys::rtcReleaseDevice(self.raw);
        }
    }
}

struct UncommittedScene {
    raw: sys::RTCScene,
}

impl UncommittedScene {
    fn commit(self, device: &Device) -> Result<Scene> {
        // SAFETY: valid scene; commit happens before any query.
        unsafe { sys::rtcCommitScene(self.raw) };
        let scene = Scene { raw: self.raw };
        device.take_error("rtcCommitScene")?;
        Ok(scene)
    }
}

/// A committed, immutable scene: safe to query from many threads at once.
pub struct Scene {
    raw: sys::RTCScene,
}

// SAFETY: a committed Embree scene is read-only and supports concurrent queries.
unsafe impl Send for Scene {}
unsafe impl Sync for Scene {}

impl Drop for Scene {
    fn drop(&mut self) {
        // SAFETY: we own one reference.
        unsafe { sys::rtcReleaseScene(self.raw) };
    }
}

/// `RTCRayHit` plus room for the `instPrimID` that Embree ≥ 4.3 (built with instance arrays)
/// writes at bytes 80..96; the 4.2 headers of embree4-sys declare only 80 bytes.
#[repr(C, align(16))]
#[derive(Clone, Copy)]
pub struct RayHitPadded {
    /// The ray and hit record Embree 4.2 declares.
    pub rh: sys::RTCRayHit,
    /// Instance-array primitive ids Embree ≥ 4.3 writes after it (unused, only room).
    pub inst_prim_id: [u32; 4],
}

/// The first hit of a ray: distance along the (unnormalised) direction and geometric normal
/// (not normalised, in world space for translated instances).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance to the hit in units of the ray direction's length.
    pub t: f32,
    /// Geometric normal, unnormalised, world space.
    pub ng: [f32; 3],
}

/// 16 rays for `rtcOccluded16`, structure of arrays as Embree wants them (64-byte aligned).
pub type Ray16 = sys::RTCRay16;

/// The lane mask of a 16-ray packet: −1 active, 0 inactive. Embree loads it with 64-byte
/// aligned vector loads, so it must be aligned like the packet.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Valid16(pub [i32; 16]);

fn occluded_args(coherent: bool) -> sys::RTCOccludedArguments {
    // What `rtcInitOccludedArguments` (a header inline function) does, with our flag.
    sys::RTCOccludedArguments {
        flags: if coherent {
            sys::RTCRayQueryFlags::COHERENT
        } else {
            sys::RTCRayQueryFlags::INCOHERENT
        },
        feature_mask: sys::RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
        context: ptr::null_mut(),
        filter: None,
        occluded: None,
    }
}

impl Scene {
    /// First hit of the ray `org + t·dir`, t in [tnear, tfar].
    pub fn intersect1(&self, org: [f32; 3], dir: [f32; 3], tnear: f32, tfar: f32) -> Option<Hit> {
        let mut rh = RayHitPadded {
            rh: sys::RTCRayHit {
                ray: sys::RTCRay {
                    org_x: org[0],
                    org_y: org[1],
                    org_z: org[2],
                    tnear,
                    dir_x: dir[0],
                    dir_y: dir[1],
                    dir_z: dir[2],
                    time: 0.0,
                    tfar,
                    mask: u32::MAX,
                    id: 0,
                    flags: 0,
                },
                hit: sys::RTCHit::default(),
            },
            inst_prim_id: [u32::MAX; 4],
        };
        let mut args = sys::RTCIntersectArguments {
            flags: sys::RTCRayQueryFlags::INCOHERENT,
            feature_mask: sys::RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
            context: ptr::null_mut(),
            filter: None,
            intersect: None,
        };
        // SAFETY: committed scene; `rh` is 16-byte aligned and 96 bytes long.
        unsafe { sys::rtcIntersect1(self.raw, &mut rh.rh, &mut args) };
        (rh.rh.hit.geomID != sys::RTC_INVALID_GEOMETRY_ID).then_some(Hit {
            t: rh.rh.ray.tfar,
            ng: [rh.rh.hit.Ng_x, rh.rh.hit.Ng_y, rh.rh.hit.Ng_z],
        })
    }

    /// Whether anything lies on `org + t·dir`, t in [tnear, tfar].
    pub fn occluded1(&self, org: [f32; 3], dir: [f32; 3], tnear: f32, tfar: f32) -> bool {
        let mut ray = sys::RTCRay {
            org_x: org[0],
            org_y: org[1],
            org_z: org[2],
            tnear,
            dir_x: dir[0],
            dir_y: dir[1],
            dir_z: dir[2],
            time: 0.0,
            tfar,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        };
        let mut args = occluded_args(false);
        // SAFETY: committed scene; `ray` is 16-byte aligned (repr align in the bindings).
        unsafe { sys::rtcOccluded1(self.raw, &mut ray, &mut args) };
        ray.tfar == f32::NEG_INFINITY
    }

    /// Traces the active lanes (`valid[i] == -1`) of a 16-ray packet with the COHERENT flag
    /// (all lanes of one call should share a direction). Afterwards a lane is occluded iff its
    /// `tfar` is `-inf` ([`Scene::lane_occluded`]).
    pub fn occluded16(&self, valid: &Valid16, rays: &mut Ray16) {
        let mut args = occluded_args(true);
        // SAFETY: committed scene; `Ray16` and `Valid16` are 64-byte aligned.
        unsafe { sys::rtcOccluded16(valid.0.as_ptr(), self.raw, rays, &mut args) };
    }

    /// Whether lane `lane` of a packet traced by [`Scene::occluded16`] hit something (Embree sets its `tfar` to −∞).
    pub fn lane_occluded(rays: &Ray16, lane: usize) -> bool {
        rays.tfar[lane] == f32::NEG_INFINITY
    }
}

/// An inactive 16-ray packet (fill the lanes you use).
pub fn empty_ray16() -> Ray16 {
    Ray16::default()
}

/// Sets flush-to-zero and denormals-are-zero on the calling thread, as Embree recommends for
/// every thread that traces. Call it from each worker (rayon `start_handler`).
pub fn set_ftz_daz() {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    {
        let mut csr: u32 = 0;
        // SAFETY: reads and writes MXCSR of this thread only. Bits 15 (FTZ) and 6 (DAZ).
        // Changing the float environment is outside Rust's model, but only ever flushes
        // denormals in this thread's SSE arithmetic, which none of our results depend on.
        unsafe {
            std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack));
            csr |= (1 << 15) | (1 << 6);
            std::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, readonly));
        }
    }
}

/// Whether FTZ and DAZ are both set on the calling thread.
pub fn ftz_daz_enabled() -> bool {
    #[cfg(any(target_arch = "x86_64", target_arch = "x86"))]
    {
        let mut csr: u32 = 0;
        // SAFETY: reads MXCSR.
        unsafe { std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack)) };
        csr & ((1 << 15) | (1 << 6)) == (1 << 15) | (1 << 6)
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "x86")))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_hit_is_padded_to_96_bytes() {
        assert_eq!(std::mem::size_of::<sys::RTCRayHit>(), 80);
        assert_eq!(std::mem::size_of::<RayHitPadded>(), 96);
        assert_eq!(std::mem::align_of::<RayHitPadded>(), 16);
        assert_eq!(std::mem::align_of::<Ray16>(), 64);
        assert_eq!(std::mem::align_of::<Valid16>(), 64);
    }

    fn quad(z: f32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        (
            vec![[0.0, 0.0, z], [1.0, 0.0, z], [1.0, 1.0, z], [0.0, 1.0, z]],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn queries_agree_on_a_quad_and_its_instances() {
        let dev = Device::new("verbose=0").unwrap();
        assert!(dev.version() >= 40000, "version {}", dev.version());
        let (p, t) = quad(0.5);
        let s = dev.triangle_scene(&p, &t).unwrap();
        let h = s
            .intersect1([0.25, 0.5, 2.0], [0.0, 0.0, -1.0], 0.0, f32::INFINITY)
            .unwrap();
        assert!((h.t - 1.5).abs() < 1e-6 && h.ng[2].abs() > 0.0);
        assert!(s
            .intersect1([1.5, 0.5, 2.0], [0.0, 0.0, -1.0], 0.0, f32::INFINITY)
            .is_none());
        assert!(s.occluded1([0.5, 0.5, 0.0], [0.0, 0.0, 1.0], 0.0, 1.0));
        assert!(!s.occluded1([0.5, 0.5, 0.0], [0.0, 0.0, 1.0], 0.0, 0.4));
        // Instances at x offsets 0 and 2: lanes over x = 0.5, 1.5, 2.5, ...
        let inst = dev
            .instance_scene(&s, &[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
            .unwrap();
        let mut rays = empty_ray16();
        let mut valid = Valid16::default();
        for lane in 0..16 {
            valid.0[lane] = if lane == 15 { 0 } else { -1 };
            rays.org_x[lane] = 0.5 + lane as f32;
            rays.org_y[lane] = 0.5;
            rays.dir_z[lane] = 1.0;
            rays.tfar[lane] = 10.0;
        }
        set_ftz_daz();
        assert!(ftz_daz_enabled());
        inst.occluded16(&valid, &mut rays);
        for lane in 0..15 {
            let expect = lane == 0 || lane == 2;
            assert_eq!(Scene::lane_occluded(&rays, lane), expect, "lane {lane}");
            let single = inst.occluded1([0.5 + lane as f32, 0.5, 0.0], [0.0, 0.0, 1.0], 0.0, 10.0);
            assert_eq!(single, expect, "single lane {lane}");
        }
        assert!(!Scene::lane_occluded(&rays, 15), "inactive lane untouched");
        dev.take_error("test").unwrap();
    }
}
