// blur/separable.wgsl: bilinear lookups in the per-light maps separable_passes.wgsl pre-blurs.
// Included into shade.wgsl by `blur::separable`; CPU twin: blur/separable.rs.

@group(0) @binding(8) var<storage, read> sep_map: array<f32>; // [light][row][col][channel]

const SEP_CHANNELS: u32 = {{CHANNELS}}u;

fn sep_tap(li: u32, x: i32, y: i32, ch: u32) -> f32 {
    let pw = i32(plane.padded.x);
    let ph = i32(plane.padded.y);
    if (x < 0 || y < 0 || x >= pw || y >= ph) {
        return 0.0;
    }
    return sep_map[(u32((i32(li) * ph + y) * pw + x)) * SEP_CHANNELS + ch];
}

// Bilinear lookup of light li's pre-blurred map (separable_passes.wgsl) at caster texel coordinate t.
fn blur_separable(li: u32, t: vec2<f32>) -> vec3<f32> {
    let c = t + vec2<f32>(plane.margin) - 0.5;
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

// The method's entry point, called by `light_opacity` (see blur/explicit.wgsl); the map of
// light li was blurred with that light's radii (a box), so `wt` and `shear` are not read.
fn blur_lookup(li: u32, t: vec2<f32>, wt: vec2<f32>, shear: f32, kernel: u32) -> vec4<f32> {
    // No fourth channel: only glossy scenes have one, and they never use this method.
    return vec4<f32>(blur_separable(li, t), 0.0);
}
