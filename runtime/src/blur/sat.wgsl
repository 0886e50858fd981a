// blur/sat.wgsl: box (rectangle) kernels from the summed-area table built by sat_build.wgsl.
// Included into shade.wgsl by `blur::sat`; CPU twin: blur/sat.rs.

@group(0) @binding(5) var<storage, read> sat: array<u32>;

const SAT_CHANNELS: u32 = {{CHANNELS}}u;

fn sat_load(i: u32, j: u32, ch: u32) -> u32 {
    return sat[(j * (plane.size.x + 1u) + i) * SAT_CHANNELS + ch];
}

// One axis of a box [lo, hi] (texel units, clamped to the table) split into whole-texel spans
// of a piecewise-constant image: corner indices [i0, i0+1, i1, i1+1] (clamped to n) and weights
// of the spans inner (c1→c2), right (c2→c3), left (c0→c1). Integral = Σ weight·span sum, exact
// for the bilinear interpolant of the table. When lo and hi share a texel the inner span is
// empty and the right span carries a1 − a0, so every span sum is non-negative.
struct Spans {
    corner: vec4<u32>,
    weight: vec3<f32>,
}

fn sat_spans(lo: f32, hi: f32, n: u32) -> Spans {
    let i0 = u32(floor(lo));
    let i1 = u32(floor(hi));
    let a0 = lo - floor(lo);
    let a1 = hi - floor(hi);
    var s: Spans;
    if (i1 > i0) {
        s.corner = vec4<u32>(i0, min(i0 + 1u, n), i1, min(i1 + 1u, n));
        s.weight = vec3<f32>(1.0, a1, 1.0 - a0);
    } else {
        s.corner = vec4<u32>(i0, i1, i1, min(i1 + 1u, n));
        s.weight = vec3<f32>(0.0, a1 - a0, 0.0);
    }
    return s;
}

// Summed-area lookup: mean opacity over the box t ± wt (texels); outside the caster counts as
// transparent, so the sum is divided by the full box area. Corner differences are taken in
// wrapping u32 (exact for any box up to 4096² texels), converted to f32 only after.
fn blur_sat(t: vec2<f32>, wt: vec2<f32>) -> vec4<f32> {
    let size = vec2<f32>(plane.size);
    let lo = clamp(t - wt, vec2<f32>(0.0), size);
    let hi = clamp(t + wt, vec2<f32>(0.0), size);
    let sx = sat_spans(lo.x, hi.x, plane.size.x);
    let sy = sat_spans(lo.y, hi.y, plane.size.y);
    var out = vec4<f32>(0.0);
    for (var ch = 0u; ch < SAT_CHANNELS; ch++) {
        var s: array<array<u32, 4>, 4>;
        for (var b = 0u; b < 4u; b++) {
            for (var a = 0u; a < 4u; a++) {
                s[b][a] = sat_load(sx.corner[a], sy.corner[b], ch);
            }
        }
        var total = 0.0;
        for (var m = 0u; m < 3u; m++) {
            // Span m of an axis runs from corner ca[m] to cb[m]: inner 1→2, right 2→3, left 0→1.
            let xa = select(select(0u, 2u, m == 1u), 1u, m == 0u);
            let xb = select(select(1u, 3u, m == 1u), 2u, m == 0u);
            for (var k = 0u; k < 3u; k++) {
                let ya = select(select(0u, 2u, k == 1u), 1u, k == 0u);
                let yb = select(select(1u, 3u, k == 1u), 2u, k == 0u);
                let span_sum = s[yb][xb] - s[yb][xa] - s[ya][xb] + s[ya][xa];
                total += sx.weight[m] * sy.weight[k] * f32(span_sum);
            }
        }
        out[ch] = total / (4.0 * wt.x * wt.y * 255.0);
    }
    if (SAT_CHANNELS == 1u) {
        return vec4<f32>(out.x);
    }
    return out;
}

// The sheared ellipse ((x − shear·y)/wt.x)² + (y/wt.y)² ≤ 1 around t as SAT_SLABS boxes, one
// per band of rows: band k spans y/wt.y ∈ [SLAB_EDGE[k], SLAB_EDGE[k + 1]] (edges at −cos(πk/4),
// thinner at the ends where the outline turns fastest), centred on the chords' midpoints there
// and as wide as the ellipse's mean chord over the band (SLAB_WIDTH: ∫√(1 − η²)dη over the band
// / its height), so each box has its band's exact area and the boxes together the ellipse's.
// Constant cost: SAT_SLABS box lookups whatever the radii.
const SAT_SLABS: u32 = 4u;
const SLAB_EDGE = array<f32, 5>(-1.0, -0.70710678, 0.0, 0.70710678, 1.0);
const SLAB_WIDTH = array<f32, 4>(0.48720514, 0.90891376, 0.90891376, 0.48720514);

fn blur_sat_ellipse(t: vec2<f32>, wt: vec2<f32>, shear: f32) -> vec4<f32> {
    var sum = vec4<f32>(0.0);
    var area = 0.0;
    for (var k = 0u; k < SAT_SLABS; k++) {
        let mid = 0.5 * (SLAB_EDGE[k] + SLAB_EDGE[k + 1u]) * wt.y;
        let hw = vec2<f32>(SLAB_WIDTH[k] * wt.x, 0.5 * (SLAB_EDGE[k + 1u] - SLAB_EDGE[k]) * wt.y);
        let a = hw.x * hw.y;
        sum += a * blur_sat(t + vec2<f32>(shear * mid, mid), hw);
        area += a;
    }
    return sum / area;
}

//#if GAUSSIAN
// The Gaussian of standard deviations wt around t as a sum of boxes: along each axis the unit
// Gaussian is approximated by GAUSS_BOXES centred boxes of half-sides GAUSS_HALF[i] (units of σ)
// and weights GAUSS_WEIGHT[i] (fitted so that the mixture's CDF, a penumbra's profile across a
// straight edge, is within 0.0071 of the normal CDF everywhere; its variance is 1.001), and
// the 2-D kernel is their product: GAUSS_BOXES² box lookups, constant cost whatever σ.
const GAUSS_BOXES: u32 = 3u;
const GAUSS_HALF = array<f32, 3>(0.77834513, 1.47147433, 2.45344008);
const GAUSS_WEIGHT = array<f32, 3>(0.24554278, 0.43724912, 0.31720809);

fn blur_sat_gauss(t: vec2<f32>, wt: vec2<f32>) -> vec4<f32> {
    var sum = vec4<f32>(0.0);
    var total = 0.0;
    for (var j = 0u; j < GAUSS_BOXES; j++) {
        for (var i = 0u; i < GAUSS_BOXES; i++) {
            let a = GAUSS_WEIGHT[i] * GAUSS_WEIGHT[j];
            sum += a * blur_sat(t, vec2<f32>(GAUSS_HALF[i] * wt.x, GAUSS_HALF[j] * wt.y));
            total += a;
        }
    }
    return sum / total;
}
//#endif

// The method's entry point, called by `light_opacity` (see blur/explicit.wgsl): the box, the
// ellipse as boxes, or the Gaussian as boxes.
fn blur_lookup(li: u32, t: vec2<f32>, wt: vec2<f32>, shear: f32, kernel: u32) -> vec4<f32> {
    if (kernel == KERNEL_DISC) {
        return blur_sat_ellipse(t, wt, shear);
    }
//#if GAUSSIAN
    if (kernel == KERNEL_GAUSS) {
        return blur_sat_gauss(t, wt);
    }
//#endif
    return blur_sat(t, wt);
}
