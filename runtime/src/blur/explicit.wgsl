// blur/explicit.wgsl: the reference blur, an explicit grid of samples over the elliptical kernel.
// Included into shade.wgsl by `blur::explicit`; CPU twin: blur/explicit.rs.

@group(0) @binding(4) var<storage, read> opacity_tex: array<u32>;

// Opacity of the texel containing texel coordinate t as 8-bit counts per channel (0 outside).
fn opacity_raw(t: vec2<f32>) -> vec4<u32> {
    let size = vec2<f32>(plane.size);
    if (t.x < 0.0 || t.y < 0.0 || t.x >= size.x || t.y >= size.y) {
        return vec4<u32>(0u);
    }
    let o = opacity_tex[u32(t.y) * plane.size.x + u32(t.x)];
    return vec4<u32>(o & 255u, (o >> 8u) & 255u, (o >> 16u) & 255u, o >> 24u);
}

// Reference blur: mean opacity over an n×n grid of samples inside the sheared ellipse of radii
// `wt` (texels) around t (a grid point o of the unit disc lands at t + (o.x·wt.x +
// shear·o.y·wt.y, o.y·wt.y)), or over the whole grid for the box kernel; n grows with the radius:
// spacing ≤ ½ texel, n ≥ 16, ≤ plane.samples. Sums are integer counts (exact, ≤ 256²·255 < 2³²),
// divided once at the end.
fn blur_explicit(t: vec2<f32>, wt: vec2<f32>, shear: f32, kernel: u32) -> vec4<f32> {
    let n = clamp(u32(ceil(4.0 * max(wt.x, wt.y))), 16u, plane.samples);
    var sum = vec4<u32>(0u);
    var count = 0u;
    for (var k = 0u; k < n * n; k++) {
        let o = (vec2<f32>(f32(k % n), f32(k / n)) + 0.5) / f32(n) * 2.0 - 1.0;
        if (kernel == KERNEL_BOX || dot(o, o) <= 1.0) {
            sum += opacity_raw(t + vec2<f32>(o.x * wt.x + shear * o.y * wt.y, o.y * wt.y));
            count += 1u;
        }
    }
    return vec4<f32>(sum) / (f32(count) * 255.0);
}

//#if GAUSSIAN
// The Gaussian of standard deviations wt around t, exactly: an n×n grid over ±GAUSS_REACH σ,
// each sample weighted by exp(−½|o|²) (o in units of σ; the tails beyond hold 3e-4 of it).
const GAUSS_REACH: f32 = 3.5;

fn blur_explicit_gauss(t: vec2<f32>, wt: vec2<f32>) -> vec4<f32> {
    let n = clamp(u32(ceil(4.0 * GAUSS_REACH * max(wt.x, wt.y))), 16u, plane.samples);
    var sum = vec4<f32>(0.0);
    var total = 0.0;
    for (var k = 0u; k < n * n; k++) {
        let o = ((vec2<f32>(f32(k % n), f32(k / n)) + 0.5) / f32(n) * 2.0 - 1.0) * GAUSS_REACH;
        let w = exp(-0.5 * dot(o, o));
        sum += w * vec4<f32>(opacity_raw(t + o * wt));
        total += w;
    }
    return sum / (total * 255.0);
}
//#endif

// The method's entry point, called by `light_opacity`: mean opacity over the kernel (a
// `blur::Kernel` number) of radii `wt` (texels) around image texel coordinate t, for light li.
fn blur_lookup(li: u32, t: vec2<f32>, wt: vec2<f32>, shear: f32, kernel: u32) -> vec4<f32> {
//#if GAUSSIAN
    if (kernel == KERNEL_GAUSS) {
        return blur_explicit_gauss(t, wt);
    }
//#endif
    return blur_explicit(t, wt, shear, kernel);
}
