// blur/sat_build.wgsl: summed-area table of an 8-bit image (the caster opacity) as u32 counts (exact; wrapping sums stay
// exact for any box up to 4096² texels). Table is (w + 1) × (h + 1) × channels, row 0 and
// column 0 zero: sat[j][i] = Σ opacity over rows < j, columns < i. Two passes, one thread per
// row (then per column) and channel, each a sequential running sum: O(w·h) work, no float.

// Field for field with `layout::SatParams`. CPU twin: blur/sat.rs.
struct SatParams {
    size: vec2<u32>, // caster w, h
    channels: u32,   // opacity channels (1 grey, 3 coloured)
    pad: u32,
}

@group(0) @binding(0) var<uniform> params: SatParams;
@group(0) @binding(1) var<storage, read> opacity_tex: array<u32>;
@group(0) @binding(2) var<storage, read_write> sat: array<u32>;

@compute @workgroup_size(64)
fn sat_rows(@builtin(global_invocation_id) id: vec3<u32>) {
    let w = params.size.x;
    let h = params.size.y;
    let channels = params.channels;
    let j = id.x / channels;
    let ch = id.x % channels;
    if (j >= h) {
        return;
    }
    var acc = 0u;
    for (var i = 0u; i < w; i++) {
        acc += (opacity_tex[j * w + i] >> (8u * ch)) & 255u;
        sat[((j + 1u) * (w + 1u) + i + 1u) * channels + ch] = acc;
    }
}

@compute @workgroup_size(64)
fn sat_columns(@builtin(global_invocation_id) id: vec3<u32>) {
    let w = params.size.x;
    let h = params.size.y;
    let channels = params.channels;
    let i = id.x / channels + 1u;
    let ch = id.x % channels;
    if (i > w) {
        return;
    }
    var acc = 0u;
    for (var j = 1u; j <= h; j++) {
        let at = (j * (w + 1u) + i) * channels + ch;
        acc += sat[at];
        sat[at] = acc;
    }
}
