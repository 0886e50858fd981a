// blur/separable_passes.wgsl: per light, a horizontal then a vertical box pass (half-sides from `radii`, in
// caster texels) over the caster opacity, with running sums at both box edges; output padded
// by margins (mx, my) so the penumbra reaches past the caster. CPU twin: blur/separable.rs.

// Field for field with `layout::SepParams`.
struct SepParams {
    size: vec2<u32>,   // caster w, h
    channels: u32,
    lights: u32,
    margin: vec2<u32>, // margins mx, my
    padded: vec2<u32>, // padded map w, h
}

@group(0) @binding(0) var<uniform> params: SepParams;
@group(0) @binding(1) var<storage, read> opacity_tex: array<u32>;
@group(0) @binding(2) var<storage, read> radii: array<vec2<f32>>; // box half-sides x, y
@group(0) @binding(3) var<storage, read_write> hmap: array<f32>; // [light][row][padded col][ch]
@group(0) @binding(4) var<storage, read_write> vmap: array<f32>; // [light][padded row][col][ch]

fn texel(j: u32, i: u32, ch: u32) -> u32 {
    if (i >= params.size.x) {
        return 0u;
    }
    return (opacity_tex[j * params.size.x + i] >> (8u * ch)) & 255u;
}

// One thread per (light, caster row, channel).
@compute @workgroup_size(64)
fn sep_h(@builtin(global_invocation_id) id: vec3<u32>) {
    let w = params.size.x;
    let h = params.size.y;
    let channels = params.channels;
    let pw = params.padded.x;
    let mx = f32(params.margin.x);
    let ch = id.x % channels;
    let j = (id.x / channels) % h;
    let li = id.x / (channels * h);
    if (li >= params.lights) {
        return;
    }
    let r = radii[li].x;
    var il = 0u;
    var pl = 0u;
    var ir = 0u;
    var pr = 0u;
    for (var i = 0u; i < pw; i++) {
        let x = f32(i) - mx + 0.5;
        let lo = clamp(x - r, 0.0, f32(w));
        let hi = clamp(x + r, 0.0, f32(w));
        while (f32(il) < floor(lo)) {
            pl += texel(j, il, ch);
            il++;
        }
        while (f32(ir) < floor(hi)) {
            pr += texel(j, ir, ch);
            ir++;
        }
        let sum = f32(pr - pl) + (hi - floor(hi)) * f32(texel(j, ir, ch))
            - (lo - floor(lo)) * f32(texel(j, il, ch));
        hmap[((li * h + j) * pw + i) * channels + ch] = sum / (2.0 * r * 255.0);
    }
}

fn hval(li: u32, j: u32, i: u32, ch: u32) -> f32 {
    let h = params.size.y;
    if (j >= h) {
        return 0.0;
    }
    return hmap[((li * h + j) * params.padded.x + i) * params.channels + ch];
}

// One thread per (light, padded column, channel).
@compute @workgroup_size(64)
fn sep_v(@builtin(global_invocation_id) id: vec3<u32>) {
    let h = params.size.y;
    let channels = params.channels;
    let pw = params.padded.x;
    let ph = params.padded.y;
    let my = f32(params.margin.y);
    let ch = id.x % channels;
    let i = (id.x / channels) % pw;
    let li = id.x / (channels * pw);
    if (li >= params.lights) {
        return;
    }
    let r = radii[li].y;
    var jl = 0u;
    var pl = 0.0;
    var jr = 0u;
    var pr = 0.0;
    for (var row = 0u; row < ph; row++) {
        let y = f32(row) - my + 0.5;
        let lo = clamp(y - r, 0.0, f32(h));
        let hi = clamp(y + r, 0.0, f32(h));
        while (f32(jl) < floor(lo)) {
            pl += hval(li, jl, i, ch);
            jl++;
        }
        while (f32(jr) < floor(hi)) {
            pr += hval(li, jr, i, ch);
            jr++;
        }
        let sum = (pr - pl) + (hi - floor(hi)) * hval(li, jr, i, ch)
            - (lo - floor(lo)) * hval(li, jl, i, ch);
        vmap[((li * ph + row) * pw + i) * channels + ch] = sum / (2.0 * r);
    }
}
