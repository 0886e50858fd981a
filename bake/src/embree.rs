//! A small safe wrapper over `embree4-sys`: device, triangle and instance geometry, committed
//! scenes, and the queries the baker needs (`rtcIntersect1`, `rtcOccluded1`, and
//! `rtcOccluded4/8/16` packets at the CPU's native width), plus FTZ/DAZ for tracing threads.
//!
//! Hazards handled here (see `/work/shared/notes/bake.md`): the config string passed to
//! `rtcNewDevice` is NUL-terminated; `rtcIntersect1` gets a 96-byte padded `RTCRayHit` because
//! Embree 4.4 built with instance arrays writes `instPrimID` past the 80-byte struct of the 4.2
//! headers, and for the same reason a ray packet has room for its hit record ([`Packet`]);
//! errors arrive through a device callback instead of a `rtcGetDeviceError` per ray.
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

    /// The widest shadow-ray packet this CPU traces natively: 16 with AVX-512, 8 with AVX2, 4
    /// with SSE; 1 if Embree has no packet kernels at all. Wider packets work everywhere but
    /// are traced one ray at a time where not native ([`Packet`]).
    pub fn packet_width(&self) -> usize {
        use sys::RTCDeviceProperty as P;
        // SAFETY: valid device; these properties are plain queries.
        let native = |p| unsafe { sys::rtcGetDeviceProperty(self.raw, p) } != 0;
        if native(P::NATIVE_RAY16_SUPPORTED) {
            16
        } else if native(P::NATIVE_RAY8_SUPPORTED) {
            8
        } else if native(P::NATIVE_RAY4_SUPPORTED) {
            4
        } else {
            1
        }
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
        let scene = self.new_scene(sys::RTCBuildQuality::MEDIUM)?;
        self.attach_triangles(&scene, positions, triangles)?;
        scene.commit(self)
    }

    /// Attaches a triangle geometry (copies of `positions` and `triangles`) to `scene`.
    fn attach_triangles(
        &self,
        scene: &UncommittedScene,
        positions: &[[f32; 3]],
        triangles: &[[u32; 3]],
    ) -> Result<()> {
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
            sys::rtcAttachGeometry(scene.raw, geom);
            sys::rtcReleaseGeometry(geom);
        }
        Ok(())
    }

    /// A scene of translated instances of `child` (one per offset), committed.
    pub fn instance_scene(&self, child: &Scene, offsets: &[[f32; 3]]) -> Result<Scene> {
        let scene = self.new_scene(sys::RTCBuildQuality::MEDIUM)?;
        self.attach_instances(&scene, child, offsets)?;
        scene.commit(self)
    }

    /// As [`Device::instance_scene`], but the copy at offset 0 is the triangles of `child`
    /// (`positions`, `triangles`, as [`Device::triangle_scene`] made it) in the scene itself,
    /// not an instance: a ray then meets that copy without Embree's instance transform and
    /// without the top level's walk to it. The same hits: Embree's identity transform leaves
    /// every origin as it is (up to the sign of a zero coordinate, which no `v − org` sees)
    /// and turns a direction's −0 into +0, so a caller gives directions without −0
    /// (`x + 0.0`), and the triangles' BVH is built by the same builder at the same quality
    /// from the same input as `child`'s. Costs a build of those triangles per scene (about
    /// 4.6 ms for 47,616 on 2 cores) and memory for them (about 90 bytes a triangle).
    pub fn centred_instance_scene(
        &self,
        child: &Scene,
        positions: &[[f32; 3]],
        triangles: &[[u32; 3]],
        offsets: &[[f32; 3]],
    ) -> Result<Scene> {
        let scene = self.new_scene(sys::RTCBuildQuality::MEDIUM)?;
        let others: Vec<[f32; 3]> = offsets.iter().copied().filter(|o| *o != [0.0; 3]).collect();
        if others.len() < offsets.len() {
            self.attach_triangles(&scene, positions, triangles)?;
        }
        self.attach_instances(&scene, child, &others)?;
        scene.commit(self)
    }

    /// Attaches a translated instance of `child` to `scene` per offset.
    fn attach_instances(
        &self,
        scene: &UncommittedScene,
        child: &Scene,
        offsets: &[[f32; 3]],
    ) -> Result<()> {
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
        Ok(())
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

/// A scene being filled; released if dropped before [`UncommittedScene::commit`] (an error
/// while attaching).
struct UncommittedScene {
    raw: sys::RTCScene,
}

impl UncommittedScene {
    fn commit(self, device: &Device) -> Result<Scene> {
        let raw = self.raw;
        // Our reference passes to the `Scene`, which releases it (also on the error below).
        std::mem::forget(self);
        // SAFETY: valid scene; commit happens before any query.
        unsafe { sys::rtcCommitScene(raw) };
        let scene = Scene { raw };
        device.take_error("rtcCommitScene")?;
        Ok(scene)
    }
}

impl Drop for UncommittedScene {
    fn drop(&mut self) {
        // SAFETY: we own one reference.
        unsafe { sys::rtcReleaseScene(self.raw) };
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
    /// The triangle hit: its index in the geometry (of the instanced tile scene, for a hit
    /// through an instance).
    pub prim: u32,
}

/// Lanes of `RTCHitN` in Embree 4.4 built with instance arrays: `Ng_x`, `Ng_y`, `Ng_z`, `u`,
/// `v`, `primID`, `geomID`, `instID[1]`, `instPrimID[1]`.
const HIT_FIELDS: usize = 9;

/// A packet of `N` rays (4, 8 or 16) for `rtcOccluded4/8/16`: the `RTCRayN` structure of arrays
/// Embree reads, then room for the `RTCHitN` that follows it in an `RTCRayHitN`.
///
/// The room is not optional. Where the CPU has no native `N`-wide kernel (16 on any CPU without
/// AVX-512, 8 without AVX2), Embree 4.4's `rtcOccludedN` traces the valid lanes one by one: it
/// treats the `RTCRayN*` as an `RTCRayHitN*`, copies each lane's ray *and hit* fields out, and
/// writes them all back (disassembly of `rtcOccluded16` in libembree4 4.4.0). On an `RTCRay16`
/// alone that reads and rewrites 576 bytes past its end: on a stack, memory of the caller's
/// frames, such as another rayon job's result and latch, written back stale while a thief
/// wrote them (bench_bake's raw loop panicked with "entered unreachable code" in rayon's
/// job.rs, or hung). The whole `RTCRayHitN` is always addressable here.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Packet<const N: usize> {
    /// Origins.
    pub org_x: [f32; N],
    /// Origins.
    pub org_y: [f32; N],
    /// Origins.
    pub org_z: [f32; N],
    /// Start of each ray (in units of its direction).
    pub tnear: [f32; N],
    /// Directions (need not be unit).
    pub dir_x: [f32; N],
    /// Directions.
    pub dir_y: [f32; N],
    /// Directions.
    pub dir_z: [f32; N],
    /// Motion-blur time (unused: 0).
    pub time: [f32; N],
    /// End of each ray; Embree sets it to −∞ on an occluded lane.
    pub tfar: [f32; N],
    /// Ray masks (all bits: every geometry).
    pub mask: [u32; N],
    /// Ray ids (unused).
    pub id: [u32; N],
    /// Ray flags (0).
    pub flags: [u32; N],
    /// The `RTCHitN` fields Embree's one-by-one fallback reads and writes back.
    hit: [[u32; N]; HIT_FIELDS],
}

impl<const N: usize> Default for Packet<N> {
    /// Zero origins and directions, `tnear` 0, `tfar` +∞, every mask bit.
    fn default() -> Self {
        Self {
            org_x: [0.0; N],
            org_y: [0.0; N],
            org_z: [0.0; N],
            tnear: [0.0; N],
            dir_x: [0.0; N],
            dir_y: [0.0; N],
            dir_z: [0.0; N],
            time: [0.0; N],
            tfar: [f32::INFINITY; N],
            mask: [u32::MAX; N],
            id: [0; N],
            flags: [0; N],
            hit: [[u32::MAX; N]; HIT_FIELDS],
        }
    }
}

impl<const N: usize> Packet<N> {
    /// Whether lane `lane` of a traced packet hit something (Embree sets its `tfar` to −∞).
    pub fn occluded(&self, lane: usize) -> bool {
        self.tfar[lane] == f32::NEG_INFINITY
    }

    /// The lanes of a traced packet that hit nothing, bit `i` for lane `i` (inactive lanes
    /// as their `tfar` reads): [`Packet::occluded`] of every lane at once, four lanes per SSE
    /// compare where the target has SSE2 (every x86-64 CPU).
    pub fn lit_mask(&self) -> u32 {
        let mut m = 0u32;
        let mut i = 0;
        #[cfg(target_arch = "x86_64")]
        while i + 4 <= N {
            use std::arch::x86_64::*;
            // SAFETY: 4 floats from lane i < N - 3 of `tfar`; SSE is part of x86-64.
            // Not equal, or unordered: `!(tfar == −∞)`, as `occluded` reads it.
            m |= unsafe {
                let t = _mm_loadu_ps(self.tfar.as_ptr().add(i));
                let lit = _mm_cmpneq_ps(t, _mm_set1_ps(f32::NEG_INFINITY));
                (_mm_movemask_ps(lit) as u32) << i
            };
            i += 4;
        }
        for lane in i..N {
            m |= (!self.occluded(lane) as u32) << lane;
        }
        m
    }
}

/// The lane mask of an `N`-ray packet: −1 active, 0 inactive. Embree loads it with aligned
/// vector loads (a 16-byte aligned mask segfaulted `rtcOccluded16` in Embree 4.4).
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Valid<const N: usize>(pub [i32; N]);

impl<const N: usize> Default for Valid<N> {
    /// No lane active.
    fn default() -> Self {
        Self([0; N])
    }
}

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
            prim: rh.rh.hit.primID,
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

    /// Traces the active lanes (`valid[i] == -1`) of an `N`-ray packet (`N` = 4, 8 or 16)
    /// with the COHERENT flag (all lanes of one call should share a direction; INCOHERENT
    /// cost 6 % more instructions per ray on the weave). Afterwards a lane is occluded iff its
    /// `tfar` is −∞ ([`Packet::occluded`]). Any `N` works on any CPU; [`Device::packet_width`]
    /// says which one Embree traces natively.
    pub fn occluded_packet<const N: usize>(&self, valid: &Valid<N>, rays: &mut Packet<N>) {
        let mut args = occluded_args(true);
        let (v, r) = (valid.0.as_ptr(), rays as *mut Packet<N>);
        // SAFETY: committed scene; the packet and the mask are 64-byte aligned, the packet is an
        // `RTCRayN` followed by room for the `RTCHitN` Embree may touch, laid out as Embree's
        // (field offsets tested below), and `N` picks the function of that width.
        unsafe {
            match N {
                4 => sys::rtcOccluded4(v, self.raw, r.cast(), &mut args),
                8 => sys::rtcOccluded8(v, self.raw, r.cast(), &mut args),
                16 => sys::rtcOccluded16(v, self.raw, r.cast(), &mut args),
                _ => panic!("Embree traces packets of 4, 8 or 16 rays, not {N}"),
            }
        }
    }
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
    use std::mem::{align_of, offset_of, size_of};

    #[test]
    fn ray_hit_is_padded_to_96_bytes() {
        assert_eq!(size_of::<sys::RTCRayHit>(), 80);
        assert_eq!(size_of::<RayHitPadded>(), 96);
        assert_eq!(align_of::<RayHitPadded>(), 16);
    }

    #[test]
    fn packets_are_embree_ray_hit_packets_with_instance_arrays() {
        // The ray part is RTCRayN field for field; the whole is RTCRayHitN of Embree 4.4
        // (RTCHitN of the 4.2 headers plus one instPrimID array).
        macro_rules! same_ray {
            ($n:literal, $sys:ty, $hit:ty) => {{
                type P = Packet<$n>;
                assert_eq!(offset_of!(P, org_x), offset_of!($sys, org_x));
                assert_eq!(offset_of!(P, org_z), offset_of!($sys, org_z));
                assert_eq!(offset_of!(P, tnear), offset_of!($sys, tnear));
                assert_eq!(offset_of!(P, dir_x), offset_of!($sys, dir_x));
                assert_eq!(offset_of!(P, time), offset_of!($sys, time));
                assert_eq!(offset_of!(P, tfar), offset_of!($sys, tfar));
                assert_eq!(offset_of!(P, mask), offset_of!($sys, mask));
                assert_eq!(offset_of!(P, flags), offset_of!($sys, flags));
                assert_eq!(offset_of!(P, hit), size_of::<$sys>());
                // Padded to 64 bytes for N = 4 and 8.
                let need = size_of::<$sys>() + size_of::<$hit>() + 4 * $n;
                assert_eq!(size_of::<P>(), need.next_multiple_of(64));
                assert_eq!(align_of::<P>(), 64);
                assert_eq!(align_of::<Valid<$n>>(), 64);
            }};
        }
        same_ray!(4, sys::RTCRay4, sys::RTCHit4);
        same_ray!(8, sys::RTCRay8, sys::RTCHit8);
        same_ray!(16, sys::RTCRay16, sys::RTCHit16);
        // What the disassembled fallback of rtcOccluded16 reaches: bytes 0..0x540.
        assert_eq!(size_of::<Packet<16>>(), 0x540);
    }

    fn quad(z: f32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        (
            vec![[0.0, 0.0, z], [1.0, 0.0, z], [1.0, 1.0, z], [0.0, 1.0, z]],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    /// Lanes over x = x0 + 0.5, x0 + 1.5, … pointing up from z = 0, `tfar` 10; the last lane
    /// inactive.
    fn up_rays<const N: usize>(rays: &mut Packet<N>, valid: &mut Valid<N>, x0: usize) {
        for lane in 0..N {
            valid.0[lane] = if lane == N - 1 { 0 } else { -1 };
            rays.org_x[lane] = 0.5 + (x0 + lane) as f32;
            rays.org_y[lane] = 0.5;
            rays.dir_z[lane] = 1.0;
            rays.tfar[lane] = 10.0;
        }
    }

    fn check_width<const N: usize>(inst: &Scene) {
        // Instances at x offsets 0 and 2: only lanes over x = 0.5 and 2.5 are occluded.
        for x0 in [0, 1] {
            let mut rays = Packet::<N>::default();
            let mut valid = Valid::<N>::default();
            up_rays(&mut rays, &mut valid, x0);
            let before = rays;
            inst.occluded_packet(&valid, &mut rays);
            for lane in 0..N - 1 {
                let x = x0 + lane;
                assert_eq!(rays.occluded(lane), x == 0 || x == 2, "width {N}, x {x}");
                let single = inst.occluded1([0.5 + x as f32, 0.5, 0.0], [0.0, 0.0, 1.0], 0.0, 10.0);
                assert_eq!(
                    single,
                    rays.occluded(lane),
                    "width {N}, single ray at x {x}"
                );
            }
            assert!(!rays.occluded(N - 1), "inactive lane untouched");
            // Nothing but tfar changes, whichever kernel (native or one by one) traced it.
            rays.tfar = before.tfar;
            assert_eq!(rays, before, "width {N}");
        }
    }

    #[test]
    fn queries_agree_on_a_quad_and_its_instances() {
        let dev = Device::new("verbose=0").unwrap();
        assert!(dev.version() >= 40000, "version {}", dev.version());
        assert!([1, 4, 8, 16].contains(&dev.packet_width()));
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
        let inst = dev
            .instance_scene(&s, &[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
            .unwrap();
        set_ftz_daz();
        assert!(ftz_daz_enabled());
        check_width::<4>(&inst);
        check_width::<8>(&inst);
        check_width::<16>(&inst);
        dev.take_error("test").unwrap();
    }

    /// Embree touches nothing past a packet's `RTCRayHitN`, whichever kernel traces it: each
    /// width's packet ends exactly where an inaccessible page begins, so a stray read or write
    /// faults. (On a CPU without AVX-512, `rtcOccluded16` is the one-by-one fallback, which
    /// reads and writes the hit fields: a bare `RTCRay16` placed so faults.)
    #[cfg(target_os = "linux")]
    #[test]
    fn packets_end_where_embree_stops_touching_memory() {
        use std::ffi::c_int;
        extern "C" {
            fn mmap(
                addr: *mut c_void,
                len: usize,
                prot: c_int,
                flags: c_int,
                fd: c_int,
                off: i64,
            ) -> *mut c_void;
            fn mprotect(addr: *mut c_void, len: usize, prot: c_int) -> c_int;
            fn munmap(addr: *mut c_void, len: usize) -> c_int;
        }
        const PAGE: usize = 4096;
        const PROT_NONE: c_int = 0;
        const PROT_RW: c_int = 1 | 2;
        const MAP_PRIVATE_ANON: c_int = 0x02 | 0x20;
        fn at_page_end<const N: usize>(inst: &Scene) {
            // SAFETY: a fresh private mapping of two pages, the second made inaccessible; the
            // packet lies inside the first, is written before it is read, and the mapping is
            // unmapped after its last use.
            unsafe {
                let base = mmap(ptr::null_mut(), 2 * PAGE, PROT_RW, MAP_PRIVATE_ANON, -1, 0);
                assert!(!base.is_null() && base as isize != -1, "mmap");
                assert_eq!(
                    mprotect(base.cast::<u8>().add(PAGE).cast(), PAGE, PROT_NONE),
                    0
                );
                let at = base.cast::<u8>().add(PAGE - size_of::<Packet<N>>());
                assert_eq!(at as usize % 64, 0);
                let rays = at.cast::<Packet<N>>();
                rays.write(Packet::default());
                let mut valid = Valid::<N>::default();
                up_rays(&mut *rays, &mut valid, 0);
                inst.occluded_packet(&valid, &mut *rays);
                assert!((*rays).occluded(0) && !(*rays).occluded(1) && (*rays).occluded(2));
                assert_eq!(munmap(base, 2 * PAGE), 0);
            }
        }
        let dev = Device::new("verbose=0").unwrap();
        let (p, t) = quad(0.5);
        let s = dev.triangle_scene(&p, &t).unwrap();
        let inst = dev
            .instance_scene(&s, &[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
            .unwrap();
        set_ftz_daz();
        at_page_end::<4>(&inst);
        at_page_end::<8>(&inst);
        at_page_end::<16>(&inst);
    }
}
