//! The shadow stage's layout does not reach the output: every packet width (1, 4, 8, 16 lanes
//! per Embree call, native or traced one by one inside Embree), thread count, grouping of lights
//! into passes and split of the rows into shards gives K, (u, v) and coverage bit for bit equal
//! to single rays, one light per pass, on one thread, on swatches with overhangs (knit loops),
//! holes (the open weave) and pile, under distant and point lights.
use ptm_bake::{BakeConfig, BakeReport, Baker, PreparedMesh};
use ptm_format::LightSet;

/// Every plane a bake hands its sink, as bits, plus coverage and the ray counts.
#[derive(Debug, PartialEq)]
struct Out {
    k: Vec<Vec<u32>>,
    uv: Vec<Vec<[u32; 2]>>,
    coverage: Vec<u32>,
    traced: u64,
    skipped: u64,
}

fn cfg(light_distance: Option<f64>, threads: usize) -> BakeConfig {
    BakeConfig {
        // Not a multiple of 4 either way: partial texel blocks at the right and bottom.
        res: [30, 26],
        spp: 4,
        seed: 7,
        light_distance,
        packets: true,
        threads,
    }
}

fn collect(out: &mut Out, index: usize, k: &[f32], uv: Option<&[[f32; 2]]>) {
    if out.k.len() <= index {
        out.k.resize(index + 1, Vec::new());
        out.uv.resize(index + 1, Vec::new());
    }
    out.k[index].extend(k.iter().map(|v| v.to_bits()));
    if let Some(uv) = uv {
        out.uv[index].extend(uv.iter().map(|p| p.map(f32::to_bits)));
    }
}

fn add(out: &mut Out, rep: &BakeReport) {
    out.traced += rep.shadow_rays;
    out.skipped += rep.shadow_rays_skipped;
}

fn empty() -> Out {
    Out {
        k: Vec::new(),
        uv: Vec::new(),
        coverage: Vec::new(),
        traced: 0,
        skipped: 0,
    }
}

/// The reference: rays one by one (`rtcOccluded1`), one thread, each light in its own
/// `trace` call (a pass of one light).
fn reference(s: &PreparedMesh, lights: &LightSet, r: Option<f64>) -> Out {
    let mut baker = Baker::new(s, &cfg(r, 1)).unwrap();
    baker.set_packet_width(1).unwrap();
    let mut out = empty();
    for (i, &d) in lights.dirs.iter().enumerate() {
        let one = LightSet::from_dirs([d]);
        let rep = baker
            .trace(&one, &mut |_, k, uv| {
                collect(&mut out, i, k, uv);
                Ok(())
            })
            .unwrap();
        add(&mut out, &rep);
    }
    out.coverage = baker.coverage().iter().map(|c| c.to_bits()).collect();
    out
}

/// All lights in one `trace` call (passes of several lights) over shards of the rows between
/// consecutive `cuts`, `width` lanes per call (0: the CPU's native width), `threads` workers.
fn bake(
    s: &PreparedMesh,
    lights: &LightSet,
    r: Option<f64>,
    width: usize,
    threads: usize,
    cuts: &[usize],
) -> Out {
    let mut out = empty();
    for rows in cuts.windows(2) {
        let mut baker = Baker::new_rows(s, &cfg(r, threads), rows[0]..rows[1]).unwrap();
        if width != 0 {
            baker.set_packet_width(width).unwrap();
        }
        let rep = baker
            .trace(lights, &mut |i, k, uv| {
                collect(&mut out, i, k, uv);
                Ok(())
            })
            .unwrap();
        add(&mut out, &rep);
        out.coverage
            .extend(baker.coverage().iter().map(|c| c.to_bits()));
    }
    out
}

fn check(spec: &str) {
    let s = PreparedMesh::load(spec, None).unwrap();
    // 11 lights: more than one pass at 30×26 (8 per pass), some low enough to need copies.
    let lights = ptm_bake::dome::fibonacci(11, 8.0).unwrap();
    let far = 4.0 * s.tile[0].max(s.tile[1]);
    for r in [None, Some(far)] {
        let want = reference(&s, &lights, r);
        assert_eq!(want.k.len(), lights.dirs.len());
        assert_eq!(want.uv.iter().all(|p| p.is_empty()), r.is_none());
        // Not a trivial scene: partly occluded texels, and rays both traced and skipped.
        let partly = want.k.iter().flatten().map(|&b| f32::from_bits(b));
        assert!(
            partly.filter(|&k| k > 0.0 && k < 1.0).count() > 100,
            "{spec}"
        );
        assert!(want.traced > 0 && want.skipped > 0, "{spec}");
        for width in [1, 4, 8, 16, 0] {
            for threads in [1, 2] {
                let got = bake(&s, &lights, r, width, threads, &[0, 26]);
                assert!(
                    got == want,
                    "{spec}, light distance {r:?}, width {width}, {threads} threads"
                );
            }
        }
        // Shards of a farm bake (row starts on multiples of 4), native width.
        let got = bake(&s, &lights, r, 0, 2, &[0, 8, 20, 26]);
        assert!(got == want, "{spec}, light distance {r:?}, shards");
    }
}

#[test]
fn widths_threads_passes_and_shards_agree_on_knit_loops() {
    check("builtin:jersey");
}

#[test]
fn widths_threads_passes_and_shards_agree_on_an_open_weave() {
    check("builtin:plain-weave");
}

#[test]
fn widths_threads_passes_and_shards_agree_on_pile() {
    check("builtin:velvet");
}
