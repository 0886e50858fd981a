// blit.wgsl: the window's pass: the renderer's `Rgba32Float` frame (`textureLoad`, nearest),
// letterboxed into the window, × 2^exposure, clamped, sRGB-encoded unless the surface format is
// sRGB already. Twin: cpu/blit.rs; `BlitParams` is `layout::BlitParams` field for field.

struct BlitParams {
    image: vec2<f32>,
    offset: vec2<f32>,
    fit: vec2<f32>,
    scale: f32,
    encode: f32,
}

@group(0) @binding(0) var frame_tex: texture_2d<f32>;
@group(0) @binding(1) var<uniform> params: BlitParams;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

fn srgb_encode(x: f32) -> f32 {
    let c = clamp(x, 0.0, 1.0);
    if c <= 0.0031308 {
        return 12.92 * c;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

@fragment
fn fs_main(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let q = (pos.xy - params.offset) / params.fit;
    if any(q < vec2<f32>(0.0)) || any(q >= vec2<f32>(1.0)) {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    let texel = vec2<i32>(min(q * params.image, params.image - 1.0));
    var c = clamp(textureLoad(frame_tex, texel, 0).rgb * params.scale, vec3<f32>(0.0), vec3<f32>(1.0));
    if params.encode > 0.5 {
        c = vec3<f32>(srgb_encode(c.r), srgb_encode(c.g), srgb_encode(c.b));
    }
    return vec4<f32>(c, 1.0);
}
