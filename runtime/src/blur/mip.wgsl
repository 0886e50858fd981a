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

// The method's entry point, called by `light_opacity` (see blur/explicit.wgsl).
fn blur_lookup(li: u32, t: vec2<f32>, wt: vec2<f32>, kernel: u32) -> vec3<f32> {
    return blur_mip(t, wt);
}
