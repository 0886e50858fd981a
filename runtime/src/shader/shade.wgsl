// shade.wgsl: the acceptor plane seen from above under spherical lights, radiance multiplied by
// (1 − K) from the occlusion PTM and by (1 − opacity) from the penumbra map of a planar caster.
//
// Source-level variants (shader/mod.rs): `//#if NAME` … `//#else` … `//#endif` lines keep or drop
// code and bindings; {{NC}}, {{PTM_EVAL}} and {{SAT_CHANNELS}} are filled in. The CPU twin is
// cpu/shade.rs: same function names, same maths.

// The uniform block, field for field with `layout::Frame` (tested against naga's offsets).
struct Frame {
    view: vec4<f32>,            // world rect x0, y0, x1, y1 of the orthographic camera
    screen: vec2<f32>,          // output width, height (px)
    tile: vec2<f32>,            // tile period W, H (swatch units) of PTM and albedo
    albedo: vec3<f32>,          // constant linear albedo rgb
    light_count: u32,
    caster_rect: vec4<f32>,     // world rect x0, y0, x1, y1 of the caster
    caster_height: f32,         // height d_ca of the caster's centre line
    caster_sin_tilt: f32,       // sin, cos of its tilt about that line (parallel to X)
    caster_cos_tilt: f32,
    explicit_samples: u32,      // explicit blur: cap on samples per axis
    ptm_size: vec2<u32>,        // PTM texels nx, ny
    albedo_size: vec2<u32>,     // albedo texels nx, ny
    caster_size: vec2<u32>,     // caster texels w, h
    sep_margin: vec2<u32>,      // separable: margins mx, my around the caster
    sep_padded: vec2<u32>,      // separable: padded map w, h
    ptm_texels_per_pixel: f32,  // at unit depth for the perspective camera
    ptm_level_count: u32,       // PTM MIP levels (0 without a chain)
    eye: vec3<f32>,             // perspective eye
    perspective: u32,           // 1 perspective, 0 orthographic top view
    cam_right: vec3<f32>,       // right · tan(fov/2) · aspect
    pad0: f32,
    cam_up: vec3<f32>,          // up · tan(fov/2)
    pad1: f32,
    cam_forward: vec3<f32>,     // forward (unit)
    pad2: f32,
}

struct Light {
    position: vec3<f32>, // centre
    radius: f32,         // sphere radius R
    color: vec3<f32>,    // colour × intensity
    pad: f32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
//#if PTM
@group(0) @binding(2) var<storage, read> coeffs: array<f32>;
//#endif
//#if ALBEDO_TEX
@group(0) @binding(3) var<storage, read> albedo_tex: array<vec4<f32>>;
//#endif
//#if BLUR_EXPLICIT
@group(0) @binding(4) var<storage, read> opacity_tex: array<u32>;
//#endif
//#if BLUR_SAT
@group(0) @binding(5) var<storage, read> sat: array<u32>;
//#endif
//#if BLUR_MIP
@group(0) @binding(6) var<storage, read> mip: array<vec4<f32>>;
// One level of the caster opacity's MIP chain (`layout::MipLevel`): its texels start at
// `offset` in `mip`.
struct MipLevel {
    offset: u32,
    width: u32,
    height: u32,
    pad: u32,
}

@group(0) @binding(7) var<storage, read> mip_levels: array<MipLevel>;
//#endif
//#if BLUR_SEPARABLE
@group(0) @binding(8) var<storage, read> sep_map: array<f32>; // [light][row][col][channel]
//#endif
//#if PTM_MIP
// One level of the PTM's MIP chain (`layout::PtmLevel`): its texels start at `offset` in
// `coeffs`; `period` is the tile's extent in this level's texels, = (width, height) when the level
// tiles exactly (a derived chain) and up to one texel more for a stored level of an odd side
// (sizes rounded down: texel i covers level-0 texels 2^k·i … 2^k·(i + 1), the rest is a gap).
struct PtmLevel {
    offset: u32,
    width: u32,
    height: u32,
    pad: u32,
    period: vec2<f32>,
    pad2: vec2<f32>,
}

@group(0) @binding(9) var<storage, read> ptm_levels: array<PtmLevel>;
//#endif
//#if PTM_COVERAGE
// Per PTM texel (levels laid out as in `coeffs`): the fraction with cloth under it, 0 in a hole.
@group(0) @binding(10) var<storage, read> coverage: array<f32>;
//#endif

// Full-screen triangle: vertices (−1, −1), (3, −1), (−1, 3).
@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32(i32(i & 1u) * 4 - 1);
    let y = f32(i32(i >> 1u) * 4 - 1);
    return vec4<f32>(x, y, 0.0, 1.0);
}

// Perspective ray direction through pixel `frag` (its forward component is 1).
fn view_dir(frag: vec2<f32>) -> vec3<f32> {
    let t = frag / frame.screen;
    return frame.cam_forward + (2.0 * t.x - 1.0) * frame.cam_right
        + (1.0 - 2.0 * t.y) * frame.cam_up;
}

// Cloth point (x, y) seen through a pixel centre and whether the pixel sees the cloth (z: 1/0);
// `frag` is @builtin(position).xy (pixel + 0.5). Orthographic: row 0 is y1 of the view.
// Perspective: the ray eye + s·dir meets z = 0 at s = −eye.z/dir.z (needs dir.z < 0 < eye.z).
fn pixel_world(frag: vec2<f32>) -> vec3<f32> {
    let t = frag / frame.screen;
    if (frame.perspective == 0u) {
        return vec3<f32>(
            frame.view.x + (frame.view.z - frame.view.x) * t.x,
            frame.view.w - (frame.view.w - frame.view.y) * t.y,
            1.0,
        );
    }
    let dir = view_dir(frag);
    if (dir.z >= 0.0 || frame.eye.z <= 0.0) {
        return vec3<f32>(0.0);
    }
    let s = -frame.eye.z / dir.z;
    return vec3<f32>(frame.eye.xy + s * dir.xy, 1.0);
}

// Four texel indices (x0y0, x1y0, x0y1, x1y1) and bilinear weights for a texture of `n` texels
// tiled with period frame.tile; texel centres at (i + 0.5)/n, row 0 at the far edge.
struct Bilinear {
    index: vec4<u32>,
    weight: vec4<f32>,
}

fn tile_bilinear(p: vec2<f32>, n: vec2<u32>) -> Bilinear {
    let s = p / frame.tile;
    let f = vec2<f32>(s.x - floor(s.x), 1.0 - (s.y - floor(s.y)));
    let c = f * vec2<f32>(n) - 0.5;
    let c0 = floor(c);
    let a = c - c0;
    let ni = vec2<i32>(n);
    let x0 = ((i32(c0.x) % ni.x) + ni.x) % ni.x;
    let y0 = ((i32(c0.y) % ni.y) + ni.y) % ni.y;
    let x1 = (x0 + 1) % ni.x;
    let y1 = (y0 + 1) % ni.y;
    var b: Bilinear;
    b.index = vec4<u32>(
        u32(y0 * ni.x + x0),
        u32(y0 * ni.x + x1),
        u32(y1 * ni.x + x0),
        u32(y1 * ni.x + x1),
    );
    b.weight = vec4<f32>((1.0 - a.x) * (1.0 - a.y), a.x * (1.0 - a.y), (1.0 - a.x) * a.y, a.x * a.y);
    return b;
}

//#if PTM
const NC: u32 = {{NC}}u;

//#if PTM_MIP
// Level of detail: log2 of the PTM texels under the pixel (frag = pixel + 0.5). Orthographic:
// the same everywhere. Perspective: the ray eye + s·dir (dir's forward component 1) meets the
// cloth at depth s = −eye.z/dir.z, where a pixel spans s·δ across the ray and s·δ·|dir|/|dir.z|
// along the plane's steepest direction; the larger side is taken (isotropic, like trilinear
// texture filtering).
fn ptm_lod(frag: vec2<f32>) -> f32 {
    var texels = frame.ptm_texels_per_pixel;
    if (frame.perspective != 0u) {
        let dir = view_dir(frag);
        texels = texels * frame.eye.z * length(dir) / (dir.z * dir.z);
    }
    return clamp(log2(max(texels, 1.0)), 0.0, f32(frame.ptm_level_count) - 1.0);
}

// One axis of `level_bilinear`: texel indices (x0, x1) and the weight of x1 at level-texel
// coordinate c ∈ [−0.5, period − 0.5) of a tiled axis of n texels. Between the last texel and
// the first of the next tile the gap spans period − n + 1 texel steps (1 when the level tiles
// exactly, then this is tile_bilinear's arithmetic bit for bit).
fn level_axis(c: f32, n: u32, period: f32) -> vec3<f32> {
    let c0 = floor(c);
    let a = c - c0;
    let x0 = i32(c0);
    let last = i32(n) - 1;
    if (x0 >= 0 && x0 < last) {
        return vec3<f32>(f32(x0), f32(x0 + 1), a);
    }
    let offset = f32(x0 - last) + select(0.0, period, x0 < 0);
    let gap = period - f32(n) + 1.0;
    return vec3<f32>(f32(last), 0.0, (a + offset) / gap);
}

// As tile_bilinear, for a MIP level whose tile spans `period` texels (see PtmLevel).
fn level_bilinear(p: vec2<f32>, lv: PtmLevel) -> Bilinear {
    let s = p / frame.tile;
    let f = vec2<f32>(s.x - floor(s.x), 1.0 - (s.y - floor(s.y)));
    let c = f * lv.period - 0.5;
    let ax = level_axis(c.x, lv.width, lv.period.x);
    let ay = level_axis(c.y, lv.height, lv.period.y);
    let x0 = u32(ax.x);
    let x1 = u32(ax.y);
    let y0 = u32(ay.x);
    let y1 = u32(ay.y);
    let a = vec2<f32>(ax.z, ay.z);
    var b: Bilinear;
    b.index = vec4<u32>(y0 * lv.width + x0, y0 * lv.width + x1, y1 * lv.width + x0, y1 * lv.width + x1);
    b.weight = vec4<f32>((1.0 - a.x) * (1.0 - a.y), a.x * (1.0 - a.y), (1.0 - a.x) * a.y, a.x * a.y);
    return b;
}

// Bilinearly filtered coefficients of MIP level `level` at p.
fn ptm_level(p: vec2<f32>, level: u32) -> array<f32, {{NC}}> {
    let lv = ptm_levels[level];
    let b = level_bilinear(p, lv);
    let i = (b.index + vec4<u32>(lv.offset)) * NC;
    var c: array<f32, {{NC}}>;
    for (var k = 0u; k < NC; k++) {
        c[k] = b.weight.x * coeffs[i.x + k] + b.weight.y * coeffs[i.y + k]
            + b.weight.z * coeffs[i.z + k] + b.weight.w * coeffs[i.w + k];
    }
    return c;
}

// Trilinear: between the two levels around `lod` (K is linear in the coefficients, so
// filtering them filters K).
fn ptm_coeffs(p: vec2<f32>, lod: f32) -> array<f32, {{NC}}> {
    let l0 = floor(lod);
    let f = lod - l0;
    var c = ptm_level(p, u32(l0));
    if (f > 0.0) {
        let c1 = ptm_level(p, u32(l0) + 1u);
        for (var k = 0u; k < NC; k++) {
            c[k] = c[k] + f * (c1[k] - c[k]);
        }
    }
    return c;
}
//#else
// Bilinearly filtered coefficients at p (K is linear in them, so filtering them filters K).
fn ptm_coeffs(p: vec2<f32>, lod: f32) -> array<f32, {{NC}}> {
    let b = tile_bilinear(p, frame.ptm_size);
    var c: array<f32, {{NC}}>;
    for (var k = 0u; k < NC; k++) {
        c[k] = b.weight.x * coeffs[b.index.x * NC + k] + b.weight.y * coeffs[b.index.y * NC + k]
            + b.weight.z * coeffs[b.index.z * NC + k] + b.weight.w * coeffs[b.index.w * NC + k];
    }
    return c;
}
//#endif

//#if PTM_COVERAGE
//#if PTM_MIP
// Bilinearly filtered coverage of MIP level `level` at p.
fn coverage_level(p: vec2<f32>, level: u32) -> f32 {
    let lv = ptm_levels[level];
    let b = level_bilinear(p, lv);
    let i = b.index + vec4<u32>(lv.offset);
    return b.weight.x * coverage[i.x] + b.weight.y * coverage[i.y] + b.weight.z * coverage[i.z]
        + b.weight.w * coverage[i.w];
}

// Coverage at p, filtered as the coefficients are (trilinear between the levels around lod).
fn ptm_coverage(p: vec2<f32>, lod: f32) -> f32 {
    let l0 = floor(lod);
    let f = lod - l0;
    var c = coverage_level(p, u32(l0));
    if (f > 0.0) {
        c = c + f * (coverage_level(p, u32(l0) + 1u) - c);
    }
    return c;
}
//#else
// Coverage at p, filtered as the coefficients are (bilinear).
fn ptm_coverage(p: vec2<f32>, lod: f32) -> f32 {
    let b = tile_bilinear(p, frame.ptm_size);
    return b.weight.x * coverage[b.index.x] + b.weight.y * coverage[b.index.y]
        + b.weight.z * coverage[b.index.z] + b.weight.w * coverage[b.index.w];
}
//#endif
//#endif

//#if PTM_HEMISPHERICAL
// Hemispherical (u, v) of the unit light direction l (l.z > 0): (θ/(π/2))·(cos φ, sin φ), θ the
// angle from the normal, so (u, v) = l.xy · θ/((π/2)·r) with r = |l.xy|. atan2(r, l.z) is well
// conditioned up to the horizon (asin(r) is not); θ/r → 1 at the zenith.
fn ptm_hemispherical(l: vec3<f32>) -> vec2<f32> {
    let r = length(l.xy);
    let s = select(1.0, atan2(r, l.z) / r, r > 1e-6);
    return l.xy * (s / 1.5707963267948966);
}
//#endif

//#if PTM_LOGISTIC
// σ(p) = 1/(1 + e^−p) from e^−|p| ≤ 1, so exp never overflows for large |p|.
fn ptm_sigmoid(p: f32) -> f32 {
    let e = exp(-abs(p));
    return select(e / (1.0 + e), 1.0 / (1.0 + e), p >= 0.0);
}
//#endif

// K of the file's link and (u, v) map for the unit direction l towards the light, clamped to
// [0, 1] after evaluation (polynomial fits overshoot at grazing angles).
fn ptm_k(c: array<f32, {{NC}}>, l: vec3<f32>) -> f32 {
//#if PTM_HEMISPHERICAL
    let uv = ptm_hemispherical(l);
//#else
    let uv = l.xy;
//#endif
    let u = uv.x;
    let v = uv.y;
//#if PTM_LOGISTIC
    let k = ptm_sigmoid({{PTM_EVAL}});
//#else
    let k = {{PTM_EVAL}};
//#endif
    return clamp(k, 0.0, 1.0);
}
//#endif

fn albedo_at(p: vec2<f32>) -> vec3<f32> {
//#if ALBEDO_TEX
    let b = tile_bilinear(p, frame.albedo_size);
    return (b.weight.x * albedo_tex[b.index.x] + b.weight.y * albedo_tex[b.index.y]
        + b.weight.z * albedo_tex[b.index.z] + b.weight.w * albedo_tex[b.index.w]).xyz;
//#else
    return frame.albedo;
//#endif
}

//#if CASTER
// Continuous caster texel coordinates (column, row from the far edge) of a caster-plane point.
fn caster_texel_coords(q: vec2<f32>) -> vec2<f32> {
    let r = frame.caster_rect;
    let size = vec2<f32>(frame.caster_size);
    return vec2<f32>((q.x - r.x) / (r.z - r.x) * size.x, (r.w - q.y) / (r.w - r.y) * size.y);
}

//#endif

//#if BLUR_EXPLICIT
// Opacity of the texel containing texel coordinate t as 8-bit counts per channel (0 outside).
fn opacity_raw(t: vec2<f32>) -> vec3<u32> {
    let size = vec2<f32>(frame.caster_size);
    if (t.x < 0.0 || t.y < 0.0 || t.x >= size.x || t.y >= size.y) {
        return vec3<u32>(0u);
    }
    let o = opacity_tex[u32(t.y) * frame.caster_size.x + u32(t.x)];
    return vec3<u32>(o & 255u, (o >> 8u) & 255u, (o >> 16u) & 255u);
}

// Reference blur: mean opacity over an n×n grid of samples inside the ellipse of radii `wt`
// (texels) around t; n grows with the radius: spacing ≤ ½ texel, n ≥ 16, ≤ counts.w. Sums are
// integer counts (exact, ≤ 256²·255 < 2³²), divided once at the end.
fn blur_explicit(t: vec2<f32>, wt: vec2<f32>) -> vec3<f32> {
    let n = clamp(u32(ceil(4.0 * max(wt.x, wt.y))), 16u, frame.explicit_samples);
    var sum = vec3<u32>(0u);
    var count = 0u;
    for (var k = 0u; k < n * n; k++) {
        let o = (vec2<f32>(f32(k % n), f32(k / n)) + 0.5) / f32(n) * 2.0 - 1.0;
        if (dot(o, o) <= 1.0) {
            sum += opacity_raw(t + o * wt);
            count += 1u;
        }
    }
    return vec3<f32>(sum) / (f32(count) * 255.0);
}
//#endif

//#if BLUR_SAT
const SAT_CHANNELS: u32 = {{SAT_CHANNELS}}u;

fn sat_load(i: u32, j: u32, ch: u32) -> u32 {
    return sat[(j * (frame.caster_size.x + 1u) + i) * SAT_CHANNELS + ch];
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
fn blur_sat(t: vec2<f32>, wt: vec2<f32>) -> vec3<f32> {
    let size = vec2<f32>(frame.caster_size);
    let lo = clamp(t - wt, vec2<f32>(0.0), size);
    let hi = clamp(t + wt, vec2<f32>(0.0), size);
    let sx = sat_spans(lo.x, hi.x, frame.caster_size.x);
    let sy = sat_spans(lo.y, hi.y, frame.caster_size.y);
    var out = vec3<f32>(0.0);
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
        return vec3<f32>(out.x);
    }
    return out;
}
//#endif

//#if BLUR_MIP
fn mip_texel(l: MipLevel, x: i32, y: i32) -> vec3<f32> {
    if (x < 0 || y < 0 || x >= i32(l.width) || y >= i32(l.height)) {
        return vec3<f32>(0.0);
    }
    return mip[l.offset + u32(y) * l.width + u32(x)].xyz;
}

// Bilinear sample of MIP `level` at level-0 texel coordinate t (transparent outside).
fn mip_bilinear(level: u32, t: vec2<f32>) -> vec3<f32> {
    let l = mip_levels[level];
    let c = t / f32(1u << level) - 0.5;
    let c0 = floor(c);
    let a = c - c0;
    let x = i32(c0.x);
    let y = i32(c0.y);
    return mix(
        mix(mip_texel(l, x, y), mip_texel(l, x + 1, y), a.x),
        mix(mip_texel(l, x, y + 1), mip_texel(l, x + 1, y + 1), a.x),
        a.y,
    );
}

// Trilinear: level log2(2·max(wt)) (box side in texels), blended between the two nearest.
fn blur_mip(t: vec2<f32>, wt: vec2<f32>) -> vec3<f32> {
    let top = arrayLength(&mip_levels) - 1u;
    let lod = clamp(log2(2.0 * max(wt.x, wt.y)), 0.0, f32(top));
    let l0 = u32(lod);
    let l1 = min(l0 + 1u, top);
    return mix(mip_bilinear(l0, t), mip_bilinear(l1, t), lod - f32(l0));
}
//#endif

//#if BLUR_SEPARABLE
const SEP_CHANNELS: u32 = {{SAT_CHANNELS}}u;

fn sep_tap(li: u32, x: i32, y: i32, ch: u32) -> f32 {
    let pw = i32(frame.sep_padded.x);
    let ph = i32(frame.sep_padded.y);
    if (x < 0 || y < 0 || x >= pw || y >= ph) {
        return 0.0;
    }
    return sep_map[(u32((i32(li) * ph + y) * pw + x)) * SEP_CHANNELS + ch];
}

// Bilinear lookup of light li's pre-blurred map (separable.wgsl) at caster texel coordinate t.
fn blur_separable(li: u32, t: vec2<f32>) -> vec3<f32> {
    let c = t + vec2<f32>(frame.sep_margin) - 0.5;
    let c0 = floor(c);
    let a = c - c0;
    let x = i32(c0.x);
    let y = i32(c0.y);
    var out = vec3<f32>(0.0);
    for (var ch = 0u; ch < SEP_CHANNELS; ch++) {
        let top = sep_tap(li, x, y, ch) * (1.0 - a.x) + sep_tap(li, x + 1, y, ch) * a.x;
        let bottom = sep_tap(li, x, y + 1, ch) * (1.0 - a.x) + sep_tap(li, x + 1, y + 1, ch) * a.x;
        out[ch] = top * (1.0 - a.y) + bottom * a.y;
    }
    if (SEP_CHANNELS == 1u) {
        return vec3<f32>(out.x);
    }
    return out;
}
//#endif

//#if CASTER
// Mean caster opacity seen from acceptor point p towards light `l` (penumbra map, direct form).
// The caster plane passes through its centre line (rect centre, height d_ca), tilted about X:
// normal n = (0, −sin θ, cos θ), in-plane axes X and e2 = (0, cos θ, sin θ). The segment from p
// to the light centre meets it at x = p + s·(light − p); the light's cone from p has radius
// w = R·s there (similar triangles: R·d_ca/(d_lc + d_ca) for a parallel caster), and the disk of
// radius w around x, projected along the ray onto the plane, has radii w along X and
// w·|cos θ + (d·e2) sin θ/(n·d)| along e2; each at least half a caster texel. A light that is not
// beyond the caster plane as seen from p (s outside [0, 1)) casts no caster shadow.
fn light_opacity(p: vec2<f32>, l: Light, li: u32) -> vec3<f32> {
    let r = frame.caster_rect;
    let centre = vec3<f32>(0.5 * (r.xy + r.zw), frame.caster_height);
    let n = vec3<f32>(0.0, -frame.caster_sin_tilt, frame.caster_cos_tilt);
    let e2 = vec3<f32>(0.0, frame.caster_cos_tilt, frame.caster_sin_tilt);
    let pp = vec3<f32>(p, 0.0);
    let ray = l.position - pp;
    let denom = dot(n, ray);
    if (denom == 0.0) {
        return vec3<f32>(0.0);
    }
    let s = dot(n, centre - pp) / denom;
    if (!(s >= 0.0 && s < 1.0)) {
        return vec3<f32>(0.0);
    }
    let off = pp + s * ray - centre;
    let q = centre.xy + vec2<f32>(off.x, dot(off, e2));
    let w = l.radius * s;
    let stretch = abs(frame.caster_cos_tilt + dot(ray, e2) * frame.caster_sin_tilt / denom);
    let texel = (r.zw - r.xy) / vec2<f32>(frame.caster_size);
    let wt = max(vec2<f32>(w, w * stretch) / texel, vec2<f32>(0.5));
    let t = caster_texel_coords(q);
//#if BLUR_SAT
    return blur_sat(t, wt);
//#endif
//#if BLUR_MIP
    return blur_mip(t, wt);
//#endif
//#if BLUR_SEPARABLE
    return blur_separable(li, t);
//#endif
//#if BLUR_EXPLICIT
    return blur_explicit(t, wt);
//#endif
}
//#endif

// Linear radiance leaving acceptor point p (normal +Z):
// Σ albedo · I · colour · max(0, n·l)/d² · (1 − opacity) · (1 − K), × coverage with one.
// `lod`: the PTM's level of detail at this pixel (0 without a MIP chain).
fn shade(p: vec2<f32>, lod: f32) -> vec3<f32> {
    let albedo = albedo_at(p);
//#if PTM
    let c = ptm_coeffs(p, lod);
//#endif
    var radiance = vec3<f32>(0.0);
    for (var i = 0u; i < frame.light_count; i++) {
        let light = lights[i];
        let to_light = vec3<f32>(light.position.xy - p, light.position.z);
        let d2 = dot(to_light, to_light);
        if (d2 <= 0.0 || to_light.z <= 0.0) {
            continue;
        }
        let l = to_light / sqrt(d2);
        var visible = vec3<f32>(1.0);
//#if PTM
        visible *= 1.0 - ptm_k(c, l);
//#endif
//#if CASTER
        // Clamped: f32 texel coordinates make box weights sum to 1 ± ulp(t)/(2w).
        visible *= 1.0 - clamp(light_opacity(p, light, i), vec3<f32>(0.0), vec3<f32>(1.0));
//#endif
        radiance += albedo * light.color * (l.z / d2) * visible;
    }
//#if PTM_COVERAGE
    // A hole shows nothing (black, as a ray that misses the cloth); partly covered texels blend.
    radiance *= ptm_coverage(p, lod);
//#endif
    return radiance;
}

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let p = pixel_world(frag.xy);
    if (p.z == 0.0) {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    var lod = 0.0;
//#if PTM_MIP
    lod = ptm_lod(frag.xy);
//#endif
    return vec4<f32>(shade(p.xy, lod), 1.0);
}
