//! The sink of `Baker::trace`, which reads one pass of lights while the threads trace the next
//! (bake/src/ring.rs): it sees every light once, in order, with the same planes as a bake whose
//! sink is slow enough that every pass waits for it; an error from it stops the trace with that
//! error, and the baker traces again afterwards as if nothing had happened.
use std::time::Duration;

use ptm_bake::{BakeConfig, Baker, PreparedMesh};

fn baker() -> Baker {
    let s = PreparedMesh::load("builtin:jersey", None).unwrap();
    let cfg = BakeConfig {
        res: [24, 20],
        spp: 4,
        seed: 3,
        light_distance: None,
        packets: true,
        threads: 2,
    };
    Baker::new(&s, &cfg).unwrap()
}

/// Every light's K plane as bits, in the order the sink saw them, with their indices; `pause`
/// is how long the sink takes per light.
fn planes(
    baker: &mut Baker,
    lights: &ptm_format::LightSet,
    pause: Duration,
) -> Vec<(usize, Vec<u32>)> {
    let mut seen = Vec::new();
    baker
        .trace(lights, &mut |i, k, uv| {
            assert!(uv.is_none(), "no (u, v) for distant lights");
            std::thread::sleep(pause);
            seen.push((i, k.iter().map(|v| v.to_bits()).collect()));
            Ok(())
        })
        .unwrap();
    seen
}

/// 37 lights: passes of 8 (`lights_per_pass` at this size), so both slots are reused several
/// times and the last pass is short.
#[test]
fn the_sink_sees_every_light_once_in_order_whatever_its_speed() {
    let lights = ptm_bake::dome::fibonacci(37, 6.0).unwrap();
    assert_eq!(ptm_bake::visibility::lights_per_pass([24, 20]), 8);
    let fast = planes(&mut baker(), &lights, Duration::ZERO);
    let slow = planes(&mut baker(), &lights, Duration::from_millis(3));
    let order: Vec<usize> = fast.iter().map(|(i, _)| *i).collect();
    assert_eq!(order, (0..37).collect::<Vec<_>>());
    assert_eq!(fast, slow, "a slow sink changed the planes it was given");
    // Not all lights alike: a mix-up of slots would go unseen otherwise.
    assert!(fast.windows(2).any(|w| w[0].1 != w[1].1));
}

#[test]
fn an_error_from_the_sink_stops_the_trace_and_leaves_the_baker_usable() {
    let lights = ptm_bake::dome::fibonacci(37, 6.0).unwrap();
    let mut b = baker();
    let mut seen = Vec::new();
    let err = b
        .trace(&lights, &mut |i, _, _| {
            seen.push(i);
            if i == 13 {
                return Err(ptm_bake::Error::Config("the sink is full".into()));
            }
            Ok(())
        })
        .unwrap_err();
    assert!(err.to_string().contains("the sink is full"), "{err}");
    assert_eq!(seen, (0..=13).collect::<Vec<_>>());
    // The same baker, again: the same planes as a fresh one.
    assert_eq!(
        planes(&mut b, &lights, Duration::ZERO),
        planes(&mut baker(), &lights, Duration::ZERO)
    );
}
