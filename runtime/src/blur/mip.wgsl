// blur/mip.wgsl: trilinear lookups in the image's MIP chain. Included into shade.wgsl by
// `blur::mip`; CPU twin: blur/mip.rs.

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

fn mip_texel(l: MipLevel, x: i32, y: i32) -> vec4<f32> {
    if (x < 0 || y < 0 || x >= i32(l.width) || y >= i32(l.height)) {
        return vec4<f32>(0.0);
    }
    return mip[l.offset + u32(y) * l.width + u32(x)];
}

// Bilinear sample of MIP `level` at level-0 texel coordinate t (transparent outside).
fn mip_bilinear(level: u32, t: vec2<f32>) -> vec4<f32> {
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

// Trilinear at level `lod` (log2 of a box side in texels), blended between the two nearest.
fn mip_trilinear(t: vec2<f32>, lod_in: f32) -> vec4<f32> {
    let top = arrayLength(&mip_levels) - 1u;
    let lod = clamp(lod_in, 0.0, f32(top));
    let l0 = u32(lod);
    let l1 = min(l0 + 1u, top);
    return mix(mip_bilinear(l0, t), mip_bilinear(l1, t), lod - f32(l0));
}

// Trilinear: level log2(2·max(wt)) (the box's side in texels).
fn blur_mip(t: vec2<f32>, wt: vec2<f32>) -> vec4<f32> {
    return mip_trilinear(t, log2(2.0 * max(wt.x, wt.y)));
}

// Elliptical weighted average from the MIP chain: the sheared ellipse ((x − shear·y)/wt.x)² +
// (y/wt.y)² ≤ 1 is the unit disc under L = [[wt.x, shear·wt.y], [0, wt.y]]; its semi-axes are
// L's singular values. The minor one picks the level: level l's bilinear texels spread a point
// with variance (2^l)²/4 per axis, the disc of radius r's own (r²/4), so l = log2(minor);
// major/minor picks the number of samples n (≤ MIP_EWA_MAX) spaced evenly along the major axis,
// each weighted by the ellipse's area in its band (∫√(1 − η²)dη, as the SAT's slabs).
const MIP_EWA_MAX: u32 = 16u;

fn ewa_area(e: f32) -> f32 {
    let c = clamp(e, -1.0, 1.0);
    return 0.5 * (c * sqrt(max(1.0 - c * c, 0.0)) + asin(c));
}

fn blur_mip_ellipse(t: vec2<f32>, wt: vec2<f32>, shear: f32) -> vec4<f32> {
    // L·Lᵀ = [[p, q], [q, r]]; its eigenvalues are the squared semi-axes.
    let p = wt.x * wt.x + shear * shear * wt.y * wt.y;
    let q = shear * wt.y * wt.y;
    let r = wt.y * wt.y;
    let m = 0.5 * (p + r);
    let d = sqrt(0.25 * (p - r) * (p - r) + q * q);
    let major = sqrt(m + d);
    let minor = sqrt(max(m - d, 1e-12));
    var axis = vec2<f32>(1.0, 0.0);
    if (d > 1e-6 * m) {
        axis = select(vec2<f32>(q, m + d - p), vec2<f32>(m + d - r, q), p >= r);
        axis = axis / length(axis);
    }
    let n = min(u32(ceil(major / minor - 1e-3)), MIP_EWA_MAX);
    let lod = log2(minor);
    var sum = vec4<f32>(0.0);
    var total = 0.0;
    for (var i = 0u; i < n; i++) {
        let e0 = -1.0 + 2.0 * f32(i) / f32(n);
        let e1 = -1.0 + 2.0 * f32(i + 1u) / f32(n);
        let w = ewa_area(e1) - ewa_area(e0);
        sum += w * mip_trilinear(t + 0.5 * (e0 + e1) * major * axis, lod);
        total += w;
    }
    return sum / total;
}

// The method's entry point, called by `light_opacity` (see blur/explicit.wgsl): a box as one
// trilinear lookup, an ellipse by EWA, and a Gaussian of standard deviations wt as the ellipse
// of the same variance (radii 2·wt: a disc of radius r has variance r²/4 per axis), so its
// unequal axes give a non-proportionally scaled lookup.
fn blur_lookup(li: u32, t: vec2<f32>, wt: vec2<f32>, shear: f32, kernel: u32) -> vec4<f32> {
    if (kernel == KERNEL_DISC) {
        return blur_mip_ellipse(t, wt, shear);
    }
//#if GAUSSIAN
    if (kernel == KERNEL_GAUSS) {
        return blur_mip_ellipse(t, 2.0 * wt, 0.0);
    }
//#endif
    return blur_mip(t, wt);
}
