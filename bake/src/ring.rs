//! The planes of two passes of lights, so that the threads trace one pass while the sink reads
//! the one before, and never wait for each other between passes ([`crate::Baker::trace`]).
//!
//! A pass's tasks (one per row of texel blocks) fill disjoint bands of 4 image rows of its
//! slot's planes; the slot's countdown reaches zero when the last of them has finished, and
//! only then are the planes read whole (by the sink, on the calling thread), and only after
//! the sink has returned are the slot's next pass's tasks spawned. That protocol is what makes
//! the raw pointers below sound: no two threads ever touch the same plane element at the same
//! time, and the mutex of each countdown orders a task's writes before the reader's reads.
//!
//! Measured on the 2-core AVX-512 Xeon (jersey 512² × 256 lights): a barrier after every pass
//! of 8 lights left each thread idle 1.1–1.8 % of the shadow pass (waiting for the other's
//! last row of the pass, then waking up for the next).

use std::sync::{Condvar, Mutex};

/// Passes held at once: the one the sink reads and the one being traced.
pub const SLOTS: usize = 2;

/// A plane's storage, written and read only through the raw pointer taken when it was made.
struct Plane<T> {
    ptr: *mut T,
    len: usize,
    /// The allocation, never touched again until the ring is dropped.
    _own: Vec<T>,
}

impl<T: Copy + Default> Plane<T> {
    fn new(len: usize) -> Self {
        let mut own = vec![T::default(); len];
        Self {
            ptr: own.as_mut_ptr(),
            len,
            _own: own,
        }
    }
}

/// How many tasks of a slot's pass are still running, and whether one of them panicked.
#[derive(Default)]
struct Countdown {
    state: Mutex<(usize, bool)>,
    zero: Condvar,
}

/// K planes (and for point lights (u, v) planes) of [`SLOTS`] passes of up to `lights` lights.
pub struct Ring {
    k: Vec<Vec<Plane<f32>>>,
    uv: Vec<Vec<Plane<[f32; 2]>>>,
    done: Vec<Countdown>,
    /// Image width and height (texels).
    size: [usize; 2],
}

// SAFETY: the planes are plain numbers; which thread may touch which part of them when is the
// protocol of the module documentation, which every `unsafe` caller below upholds.
unsafe impl Send for Ring {}
unsafe impl Sync for Ring {}

impl Ring {
    /// Room for `slots` passes of `lights` lights over an image of `size` texels, with (u, v)
    /// planes if `uv`.
    pub fn new(slots: usize, lights: usize, size: [usize; 2], uv: bool) -> Self {
        let n = size[0] * size[1];
        Self {
            k: (0..slots)
                .map(|_| (0..lights).map(|_| Plane::new(n)).collect())
                .collect(),
            uv: (0..slots)
                .map(|_| {
                    (0..lights)
                        .map(|_| Plane::new(if uv { n } else { 0 }))
                        .collect()
                })
                .collect(),
            done: (0..slots).map(|_| Countdown::default()).collect(),
            size,
        }
    }

    /// Arms slot `slot` for a pass of `tasks` tasks (before any of them is spawned).
    pub fn start(&self, slot: usize, tasks: usize) {
        let mut s = self.done[slot]
            .state
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        *s = (tasks, false);
    }

    /// A guard that counts one task of slot `slot` as finished when dropped, also when the
    /// task unwinds (so the reader never waits for a task that will not finish).
    pub fn finisher(&self, slot: usize) -> Finisher<'_> {
        Finisher {
            countdown: &self.done[slot],
        }
    }

    /// Waits until every task of slot `slot`'s pass has finished; false if one panicked (its
    /// planes are then not to be read; the scope re-raises the panic).
    pub fn wait(&self, slot: usize) -> bool {
        let c = &self.done[slot];
        let mut s = c.state.lock().unwrap_or_else(|e| e.into_inner());
        while s.0 > 0 {
            s = c.zero.wait(s).unwrap_or_else(|e| e.into_inner());
        }
        !s.1
    }

    /// Rows `4·band ..` (4, fewer at the bottom) of plane `j` of slot `slot`: K, and (u, v)
    /// (empty without (u, v) planes).
    ///
    /// # Safety
    /// Only the one task of `band` of the slot's current pass may hold these rows, and only
    /// between [`Ring::start`] and the drop of its [`Finisher`].
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn rows_mut(
        &self,
        slot: usize,
        j: usize,
        band: usize,
    ) -> (&mut [f32], &mut [[f32; 2]]) {
        let [nx, ny] = self.size;
        let (start, end) = ((4 * band).min(ny) * nx, (4 * band + 4).min(ny) * nx);
        let (k, uv) = (&self.k[slot][j], &self.uv[slot][j]);
        // SAFETY: `start..end` lies within the plane (`end` ≤ nx·ny), and by the caller's
        // contract no other reference to these rows exists while the slice lives.
        unsafe {
            (
                std::slice::from_raw_parts_mut(k.ptr.add(start), end - start),
                match uv.len {
                    0 => &mut [],
                    _ => std::slice::from_raw_parts_mut(uv.ptr.add(start), end - start),
                },
            )
        }
    }

    /// Plane `j` of slot `slot`, whole: K, and (u, v) if the ring holds them.
    ///
    /// # Safety
    /// Only after [`Ring::wait`] on the slot returned true and before the slot's next
    /// [`Ring::start`].
    pub unsafe fn plane(&self, slot: usize, j: usize) -> (&[f32], Option<&[[f32; 2]]>) {
        let (k, uv) = (&self.k[slot][j], &self.uv[slot][j]);
        // SAFETY: every task that wrote the slot has finished (the countdown's mutex orders
        // its writes before this read), and none writes it again until the next `start`.
        unsafe {
            (
                std::slice::from_raw_parts(k.ptr, k.len),
                (uv.len > 0).then(|| std::slice::from_raw_parts(uv.ptr, uv.len)),
            )
        }
    }
}

/// Counts one task as finished when dropped ([`Ring::finisher`]).
pub struct Finisher<'r> {
    countdown: &'r Countdown,
}

impl Drop for Finisher<'_> {
    fn drop(&mut self) {
        let mut s = self
            .countdown
            .state
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        s.0 -= 1;
        s.1 |= std::thread::panicking();
        if s.0 == 0 {
            self.countdown.zero.notify_all();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bands of a pass written by tasks on a pool while the calling thread reads the pass
    /// before: every plane read holds exactly what its pass wrote, bottom band included.
    #[test]
    fn passes_overlap_without_mixing() {
        let (nx, ny, lights, passes) = (5usize, 10usize, 3, 7);
        let bands = ny.div_ceil(4);
        let ring = Ring::new(SLOTS, lights, [nx, ny], true);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        let value = |p: usize, j: usize, i: usize| (p * 1000 + j * 100 + i) as f32;
        let mut seen = 0;
        pool.in_place_scope(|s| {
            let spawn = |p: usize| {
                let slot = p % SLOTS;
                ring.start(slot, bands);
                for band in 0..bands {
                    let ring = &ring;
                    s.spawn(move |_| {
                        let _done = ring.finisher(slot);
                        for j in 0..lights {
                            // SAFETY: this task owns `band` of the slot's pass.
                            let (k, uv) = unsafe { ring.rows_mut(slot, j, band) };
                            for (o, (k, uv)) in k.iter_mut().zip(uv).enumerate() {
                                let i = band * 4 * nx + o;
                                *k = value(p, j, i);
                                *uv = [value(p, j, i), -value(p, j, i)];
                            }
                        }
                    });
                }
            };
            for p in 0..SLOTS.min(passes) {
                spawn(p);
            }
            for p in 0..passes {
                assert!(ring.wait(p % SLOTS));
                for j in 0..lights {
                    // SAFETY: the slot's pass is done and its next not started.
                    let (k, uv) = unsafe { ring.plane(p % SLOTS, j) };
                    let uv = uv.unwrap();
                    for i in 0..nx * ny {
                        assert_eq!(k[i], value(p, j, i));
                        assert_eq!(uv[i], [value(p, j, i), -value(p, j, i)]);
                    }
                    seen += 1;
                }
                if p + SLOTS < passes {
                    spawn(p + SLOTS);
                }
            }
        });
        assert_eq!(seen, passes * lights);
    }

    /// A task that panics still counts down: the reader learns of it instead of waiting
    /// forever, and the scope re-raises the panic.
    #[test]
    fn a_panicking_task_does_not_hang_the_reader() {
        let ring = Ring::new(1, 1, [4, 8], false);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.in_place_scope(|s| {
                ring.start(0, 2);
                for band in 0..2 {
                    let ring = &ring;
                    s.spawn(move |_| {
                        let _done = ring.finisher(0);
                        if band == 1 {
                            panic!("task {band}");
                        }
                    });
                }
                assert!(!ring.wait(0));
            })
        }));
        assert!(caught.is_err());
    }
}
