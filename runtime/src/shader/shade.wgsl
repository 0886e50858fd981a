// shade.wgsl: the acceptor plane seen from above under spherical lights, radiance multiplied by
// (1 − K) from the occlusion PTM and by (1 − opacity) from the penumbra map of a planar caster.
//
// Source-level variants (shader/mod.rs): `//#if NAME` … `//#else` … `//#endif` lines keep or drop
// code and bindings; {{NC}} and {{PTM_EVAL}} are filled in, and the BLUR placeholder near the end
// by the blur method's file (blur/*.wgsl: its bindings and `blur_lookup`). The CPU twin is
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
    pad3: u32,
    ptm_size: vec2<u32>,        // PTM texels nx, ny
    albedo_size: vec2<u32>,     // albedo texels nx, ny
    ptm_texels_per_pixel: f32,  // at unit depth for the perspective camera
    ptm_level_count: u32,       // PTM MIP levels (0 without a chain)
    pad4: vec2<u32>,
    eye: vec3<f32>,             // perspective eye
    perspective: u32,           // 1 perspective, 0 orthographic top view
    cam_right: vec3<f32>,       // right · tan(fov/2) · aspect
    pad0: f32,
    cam_up: vec3<f32>,          // up · tan(fov/2)
    pad1: f32,
    cam_forward: vec3<f32>,     // forward (unit)
    pad2: f32,
    fill: vec3<f32>,            // mesh: fill light (not darkened by K)
    sheen_roughness: f32,       // mesh: glTF sheenRoughnessFactor
    sheen_color: vec3<f32>,     // mesh: glTF sheenColorFactor
    near: f32,                  // mesh: near plane (depth 0)
    normal_size: vec2<u32>,     // mesh: normal map texels nx, ny
    far: f32,                   // mesh: far plane (depth 1)
    pad5: f32,
    shadow_lo: vec3<f32>,       // mesh: low corner of the box the shadow maps frame (the mesh's)
    shadow_size: u32,           // mesh: shadow map side (texels; 0 without macro shadow)
    shadow_hi: vec3<f32>,       // mesh: its high corner
    pad6: f32,
    glossy_background: vec3<f32>, // glossy receiver: background radiance (linear)
    glossy_alpha: f32,          // glossy receiver: the lobe's cone half-angle α (radians)
    glossy_rings: u32,          // glossy receiver: nested cones the lobe is averaged as (1–4)
    pad7: f32,
    pad8: f32,
    glossy_f0: f32,             // glossy receiver: Schlick's F0
}

struct Light {
    position: vec3<f32>, // centre; a distant light's unit direction
    radius: f32,         // sphere radius R; a distant light's sin(angular radius)
    color: vec3<f32>,    // colour × intensity
    shape: u32,          // 0 sphere, 1 rectangle facing down, 2 sphere as a box, 3 Gaussian, 4 glossy lobe, 5 distant
    half: vec2<f32>,     // rectangle: half-sides along X, Y; Gaussian: σ along X, Y
    axis: vec2<f32>,     // rectangle: side a's direction (cos θ, sin θ); else (1, 0)
}

// `Light::shape` of a distant light (`LightGpu::DISTANT`).
const LIGHT_DISTANT: u32 = 5u;

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
//#if PTM
@group(0) @binding(2) var<storage, read> coeffs: array<f32>;
//#endif
//#if ALBEDO_TEX
@group(0) @binding(3) var<storage, read> albedo_tex: array<vec4<f32>>;
//#endif
//#if NORMAL_MAP
// Tangent-space normals (xyz, +Y up, MikkTSpace), tiled with the PTM (mesh path only).
@group(0) @binding(12) var<storage, read> normal_tex: array<vec4<f32>>;
//#endif
//#if CASTER
// The filtered planar image the blur method convolves (`layout::PlaneGpu`); its texels and
// tables are the method's own bindings, in the method's WGSL file (blur/*.wgsl), included below.
struct Plane {
    size: vec2<u32>,            // texels w, h
    margin: vec2<u32>,          // separable: margins mx, my around the image
    padded: vec2<u32>,          // separable: padded map w, h
    samples: u32,               // explicit: cap on samples per axis
    pad: u32,
}

@group(0) @binding(11) var<uniform> plane: Plane;
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
//#if PTM_LEARNED
// A learned basis's NC tables B_k (`ptm_format::LearnedTable`, shared by every MIP level),
// node-major in vec4s: the NC values of grid node (column i, row j) fill the LEARNED_QUADS
// texels (i·LEARNED_QUADS + q, j), q = 0, 1, …, zero after the NC values (`scene::node_major`),
// so each bilinear tap is ⌈NC/4⌉ texel loads rather than NC scalar ones. A texture, not a
// storage buffer: a CPU rasteriser (lavapipe) fetches texels in SIMD where it gathers storage
// loads lane by lane. Its texels are the f32 bits as u32 (`learned_node`): an integer format
// is never filterable, so it binds without FLOAT32_FILTERABLE, and the bits come back exactly.
@group(0) @binding(13) var learned: texture_2d<u32>;
//#endif

//#if MESH
//#else
// Full-screen triangle: vertices (−1, −1), (3, −1), (−1, 3).
@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32(i32(i & 1u) * 4 - 1);
    let y = f32(i32(i >> 1u) * 4 - 1);
    return vec4<f32>(x, y, 0.0, 1.0);
}
//#endif

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

//#if PTM_LEARNED
// Grid side G of the tables: node i of an axis at u = −1 + 2i/(G − 1) (v likewise, rows j).
const LEARNED_GRID: u32 = {{GRID}}u;

// The four nodes (x0y0, x1y0, x0y1, x1y1) of the table cell holding hemispherical (u, v) and
// their bilinear weights, as `ptm_format::learned::bilinear`: (u, v) clamped to [−1, 1]², grid
// coordinates x = (u + 1)/2 · (G − 1) clamped to [0, G − 1], the cell's lower node at most
// G − 2, so u = 1 reads node G − 1 with weight 1 (and beyond the square, the edge).
fn learned_bilinear(uv: vec2<f32>) -> Bilinear {
    let s = f32(LEARNED_GRID - 1u);
    let x = clamp((clamp(uv, vec2<f32>(-1.0), vec2<f32>(1.0)) + 1.0) * 0.5 * s, vec2<f32>(0.0), vec2<f32>(s));
    let i0 = min(vec2<u32>(floor(x)), vec2<u32>(LEARNED_GRID - 2u));
    let a = x - vec2<f32>(i0);
    let c = i0.y * LEARNED_GRID + i0.x;
    var b: Bilinear;
    b.index = vec4<u32>(c, c + 1u, c + LEARNED_GRID, c + LEARNED_GRID + 1u);
    b.weight = vec4<f32>((1.0 - a.x) * (1.0 - a.y), a.x * (1.0 - a.y), (1.0 - a.x) * a.y, a.x * a.y);
    return b;
}

// vec4s per grid node: NC rounded up to whole vec4s.
const LEARNED_QUADS: u32 = (NC + 3u) / 4u;

// Terms 4q … 4q + 3 of grid node `node` (= j·G + i): texel (i·LEARNED_QUADS + q, j).
fn learned_node(node: u32, q: u32) -> vec4<f32> {
    let x = (node % LEARNED_GRID) * LEARNED_QUADS + q;
    return bitcast<vec4<f32>>(textureLoad(learned, vec2<u32>(x, node / LEARNED_GRID), 0));
}

// p = Σ_k c_k·B_k(u, v): each table read bilinearly at (u, v), dotted with the coefficients;
// per term the same operations in the same order as the twin (`Twin::learned_eval`).
fn learned_eval(c: array<f32, {{NC}}>, uv: vec2<f32>) -> f32 {
    let b = learned_bilinear(uv);
    let i = b.index;
    var p = 0.0;
    for (var q = 0u; q < LEARNED_QUADS; q++) {
        let t = b.weight.x * learned_node(i.x, q) + b.weight.y * learned_node(i.y, q)
            + b.weight.z * learned_node(i.z, q) + b.weight.w * learned_node(i.w, q);
        // Past the last term (k ≥ NC) the coefficient is 0 and the padding's table value is
        // 0: a padded term adds 0·0, and p keeps the CPU twin's value bit for bit.
        let k = vec4<u32>(4u * q) + vec4<u32>(0u, 1u, 2u, 3u);
        let m = min(k, vec4<u32>(NC - 1u));
        let ck = select(vec4<f32>(0.0), vec4<f32>(c[m.x], c[m.y], c[m.z], c[m.w]), k < vec4<u32>(NC));
        p += ck.x * t.x;
        p += ck.y * t.y;
        p += ck.z * t.z;
        p += ck.w * t.w;
    }
    return p;
}

// The predictor's jet at (u, v) for `ptm_k_area`: the same four nodes as `learned_eval`, each
// dotted with the coefficients (d = node values of p), then p and its derivatives within the
// cell: bilinear in the grid coordinates, (G − 1)/2 of them per unit of u or v.
fn learned_jet(c: array<f32, {{NC}}>, uv: vec2<f32>) -> PtmJet {
    let b = learned_bilinear(uv);
    let i = b.index;
    var d = vec4<f32>(0.0);
    for (var q = 0u; q < LEARNED_QUADS; q++) {
        let k = vec4<u32>(4u * q) + vec4<u32>(0u, 1u, 2u, 3u);
        let m = min(k, vec4<u32>(NC - 1u));
        let ck = select(vec4<f32>(0.0), vec4<f32>(c[m.x], c[m.y], c[m.z], c[m.w]), k < vec4<u32>(NC));
        d += vec4<f32>(dot(ck, learned_node(i.x, q)), dot(ck, learned_node(i.y, q)),
            dot(ck, learned_node(i.z, q)), dot(ck, learned_node(i.w, q)));
    }
    // The cell coordinates from the weights: a = (w1 + w3, w2 + w3).
    let a = vec2<f32>(b.weight.y + b.weight.w, b.weight.z + b.weight.w);
    let s = 0.5 * f32(LEARNED_GRID - 1u);
    var j: PtmJet;
    j.p = dot(b.weight, d);
    j.g = s * vec2<f32>(mix(d.y - d.x, d.w - d.z, a.y), mix(d.z - d.x, d.w - d.y, a.x));
    j.h = vec3<f32>(0.0, s * s * (d.x - d.y - d.z + d.w), 0.0);
    return j;
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

// ---- Area lights: K averaged over the light's footprint ----
// Shading needs the mean of K over the directions to an area light, weighted as its irradiance
// is (cos θ over the solid angle it subtends), not K at its centre; for the logistic link the
// mean of σ is not σ at the mean. `ptm_footprint` gives those directions' weighted mean and
// covariance C in the PTM's (u, v); `ptm_k_area` expands the predictor to second order about
// that mean (its value p, gradient g and Hessian H: `ptm_jet`), so over the footprint it has
// mean m = p + ½·tr(H·C) and variance v = gᵀ·C·g, and the mean of σ over it is taken as
// σ(m/√(1 + π·v/8)) (MacKay's probit approximation of a logistic averaged over a Gaussian: one
// σ, as a point light costs); the identity link's K is m itself. A point light has an empty
// footprint and gets `ptm_k` itself, bit for bit. docs/model.md, "Area lights", has the
// derivation and the errors against Monte Carlo.

// The predictor's value p, gradient g = (∂p/∂u, ∂p/∂v) and Hessian h = (∂²p/∂u², ∂²p/∂u∂v,
// ∂²p/∂v²) at one (u, v).
struct PtmJet {
    p: f32,
    g: vec2<f32>,
    h: vec3<f32>,
}

// Where a light's directions fall in (u, v), irradiance-weighted: their mean `centre` and
// covariance `cov` (uu, uv, vv); cov = 0 for a point light.
struct Footprint {
    centre: vec2<f32>,
    cov: vec3<f32>,
}

// The jet of the file's basis, generated from its monomials or its tables (shader/mod.rs,
// `ptm_jet_expr`).
fn ptm_jet(c: array<f32, {{NC}}>, uv: vec2<f32>) -> PtmJet {
    let u = uv.x;
    let v = uv.y;
    return {{PTM_JET}};
}

// Irradiance-weighted moments of a spherical light's cap of angular radius rho, seen at
// θ from the zenith (r = sin θ, z = cos θ): (mean, variance) of the radial angle t (away from
// the zenith) and the variance of the tangential one, in radians. The cap is taken as the disc
// |t| ≤ rho in its azimuthal-equidistant plane, the weight cos θ as linear across it,
// z − r·t_radial, and clipped where that reaches 0 (the horizon, to first order): with
// q = rho·r/z ≤ 1 the whole disc is above it, else the segment x < 1/q (units of rho) is kept,
// whose moments are Iₙ = ∫ xⁿ √(1 − x²) dx from −1 to 1/q in closed form.
fn cap_moments(rho: f32, r: f32, z: f32) -> vec3<f32> {
    let q = rho * r / z;
    // E[x], E[x²], E[y²] of the unit disc under the weight 1 − q·x.
    var e = vec3<f32>(-0.25 * q, 0.25, 0.25);
    if (q > 1.0) {
        let h = 1.0 / q;
        let s = sqrt(max(1.0 - h * h, 0.0));
        let a = asin(h);
        let s3 = s * s * s;
        let i0 = 0.5 * (h * s + a) + 0.7853981633974483;
        let i1 = -s3 / 3.0;
        let i2 = (a - h * s * (1.0 - 2.0 * h * h)) / 8.0 + 0.19634954084936207;
        let i3 = -s3 / 3.0 + s3 * s * s / 5.0;
        let w = h * i0 - i1;
        e = vec3<f32>((h * i1 - i2) / w, (h * i2 - i3) / w, (h * (i0 - i2) - (i1 - i3)) / (3.0 * w));
    }
    return vec3<f32>(rho * e.x, rho * rho * max(e.y - e.x * e.x, 0.0), rho * rho * e.z);
}

// The footprint of `light` seen from a cloth point in unit direction l at distance d. Both
// shapes are first worked out as angles along the radial and tangential axes of l (away from
// the zenith and around it), then scaled to (u, v) by the map's derivatives there and turned
// to (u, v). Sphere: the cap of angular radius asin(min(R/d, 1)) (`cap_moments`). Rectangle
// facing down (half-sides `half`, variance v = half²/3 per axis) or Gaussian (σ = `half`,
// v = σ²): its points weigh cos·cos/r² = z²/r⁴, which moves their mean by −4·v·D/d² towards
// the point (first order in half/d; D = to_light.xy; at most half/2), variance v less that
// shift²; a point (x, y) on it turns the direction by
// (cos θ·x_radial, x_tangential)/d. To second order the map bends both: a tangential angle t
// moves (u, v) towards the zenith by t²·(θ − sin θ cos θ)/(2 sin² θ)/(π/2) (hemispherical),
// and any angle t by t²·sin θ/2 (projected, where the mean of l.xy is what (u, v) averages).
fn ptm_footprint(l: vec3<f32>, to_light: vec3<f32>, d: f32, light: Light) -> Footprint {
    var f: Footprint;
    if ((light.shape == 0u || light.shape == LIGHT_DISTANT) && !(light.radius > 0.0)) {
        return f;
    }
    let r = length(l.xy);
    let axis = select(vec2<f32>(1.0, 0.0), l.xy / r, r > 1e-6);
    // Mean (radial, tangential) angle and covariance (rr, rt, tt), radians.
    var mean = vec2<f32>(0.0);
    var cov = vec3<f32>(0.0);
    var planar = light.shape == 1u;
    var v0 = light.half * light.half / 3.0;
    // A planar light's moments in its own frame (a turned rectangle's sides along its axes):
    // the direction to it and the radial axis turned into that frame.
    let b = light.axis;
    let tl = vec2<f32>(dot(to_light.xy, b), b.x * to_light.y - b.y * to_light.x);
    let al = vec2<f32>(dot(axis, b), b.x * axis.y - b.y * axis.x);
//#if GAUSSIAN
    if (light.shape == 3u) {
        planar = true;
        v0 = light.half * light.half;
    }
//#endif
    if (planar) {
        let shift = clamp(-4.0 * v0 * tl / (d * d), -0.5 * light.half, 0.5 * light.half);
        let var_xy = max(v0 - shift * shift, vec2<f32>(0.0));
        let sc = vec2<f32>(l.z, 1.0) / d;
        mean = sc * vec2<f32>(dot(al, shift), al.x * shift.y - al.y * shift.x);
        let ax2 = al * al;
        cov = vec3<f32>(
            sc.x * sc.x * (ax2.x * var_xy.x + ax2.y * var_xy.y),
            sc.x * sc.y * al.x * al.y * (var_xy.y - var_xy.x),
            sc.y * sc.y * (ax2.y * var_xy.x + ax2.x * var_xy.y),
        );
    } else {
        let m = cap_moments(asin(min(light.radius / d, 1.0)), r, l.z);
        mean = vec2<f32>(m.x, 0.0);
        cov = vec3<f32>(m.y, 0.0, m.z);
    }
    // Second moments about the centre direction, radial and tangential.
    let second = vec2<f32>(cov.x, cov.z) + mean * mean;
//#if PTM_HEMISPHERICAL
    // (u, v) = l.xy·(θ/r)/(π/2) as `ptm_hemispherical`: d(u, v)/dθ radially is 1/(π/2), and
    // tangentially an angle δ moves (u, v) by δ·(θ/sin θ)/(π/2); with s = θ/r the bend is
    // (s − cos θ)/(2r) (→ θ/3 at the zenith, where it is left out).
    let s = select(1.0, atan2(r, l.z) / r, r > 1e-6);
    let centre = l.xy * (s / 1.5707963267948966);
    let jac = vec2<f32>(1.0, s) / 1.5707963267948966;
    let bend = select(0.0, (s - l.z) / (2.0 * r), r > 1e-4) * second.y / 1.5707963267948966;
//#else
    // (u, v) = l.xy: radially d sin θ = cos θ dθ, tangentially 1.
    let centre = l.xy;
    let jac = vec2<f32>(l.z, 1.0);
    let bend = 0.5 * r * (second.x + second.y);
//#endif
    let m = jac * mean - vec2<f32>(bend, 0.0);
    let c = vec3<f32>(jac.x * jac.x * cov.x, jac.x * jac.y * cov.y, jac.y * jac.y * cov.z);
    let t = vec2<f32>(-axis.y, axis.x);
    let ab = axis.x * axis.y;
    f.centre = centre + m.x * axis + m.y * t;
    f.cov = vec3<f32>(
        c.x * axis.x * axis.x - 2.0 * c.y * ab + c.z * axis.y * axis.y,
        (c.x - c.z) * ab + c.y * (axis.x * axis.x - axis.y * axis.y),
        c.x * axis.y * axis.y + 2.0 * c.y * ab + c.z * axis.x * axis.x,
    );
    return f;
}

// K averaged over the footprint `f` of a light in direction l (see above).
fn ptm_k_area(c: array<f32, {{NC}}>, l: vec3<f32>, f: Footprint) -> f32 {
    if (!(f.cov.x + f.cov.z > 0.0)) {
        return ptm_k(c, l);
    }
    let j = ptm_jet(c, f.centre);
    let m = j.p + 0.5 * (j.h.x * f.cov.x + 2.0 * j.h.y * f.cov.y + j.h.z * f.cov.z);
//#if PTM_LOGISTIC
    let v = max(j.g.x * j.g.x * f.cov.x + 2.0 * j.g.x * j.g.y * f.cov.y + j.g.y * j.g.y * f.cov.z, 0.0);
    let k = ptm_sigmoid(m / sqrt(1.0 + 0.39269908169872414 * v));
//#else
    let k = m;
//#endif
    return clamp(k, 0.0, 1.0);
}

//#if DISTANT
// ---- Distant lights: the basis evaluated once per frame ----
// Under a distant light every point of the (flat) cloth sees the same directions, so K's
// footprint and the basis's jet there are the same everywhere; only the coefficients vary.
// The jet is linear in them, so the CPU evaluates it per term once per frame
// (`cpu::shade::distant_terms`) and each pixel dots its coefficients with three runs of NC
// values: p̄ = c·m (the mean, ½·tr(H·C) included), g = (c·g_u, c·g_v). That is the cost of a
// PTM with its monomials precomputed, whatever the basis (tables included).
// Per light TERM_STRIDE vec4s: the footprint's covariance (uu, uv, vv, 0), then m, g_u, g_v in
// ⌈NC/4⌉ vec4s each (zeros past NC); zeros for a light that is not distant.
const TERM_STRIDE: u32 = 1u + 3u * ((NC + 3u) / 4u);
// A uniform block: every pixel reads the same address (the light's), which a GPU's constant
// cache broadcasts; from a storage buffer lavapipe took 1.3–1.4× the frame's time (ptm11, one
// and four lights), more than a local light's per-pixel jet, from this block no more.
@group(0) @binding(17) var<uniform> light_terms: array<vec4<f32>, {{LIGHT_TERMS_LEN}}>;

// K under distant light `li`, as `ptm_k_area` from the precomputed terms.
fn distant_k(c: array<f32, {{NC}}>, li: u32) -> f32 {
    let base = li * TERM_STRIDE;
    let cov = light_terms[base].xyz;
    var m = 0.0;
    var g = vec2<f32>(0.0);
    // Per vec4 q of the terms: m += dot(c_q, m_q), g.x, g.y likewise (shader/mod.rs,
    // `distant_dots`: unrolled, constant indices).
{{DISTANT_DOTS}}
//#if PTM_LOGISTIC
    let v = max(g.x * g.x * cov.x + 2.0 * g.x * g.y * cov.y + g.y * g.y * cov.z, 0.0);
    let k = ptm_sigmoid(m / sqrt(1.0 + 0.39269908169872414 * v));
//#else
    let k = m;
//#endif
    return clamp(k, 0.0, 1.0);
}
//#endif
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
    let size = vec2<f32>(plane.size);
    return vec2<f32>((q.x - r.x) / (r.z - r.x) * size.x, (r.w - q.y) / (r.w - r.y) * size.y);
}
//#endif

//#if CASTER
// Mean caster opacity seen from acceptor point p towards light `l` (penumbra map, direct form).
// The caster plane passes through its centre line (rect centre, height d_ca), tilted about X:
// normal n = (0, −sin θ, cos θ), in-plane axes X and e2 = (0, cos θ, sin θ). The segment from p
// to the light centre meets it at x = p + s·(light − p); the light's cone from p has radius
// w = R·s there (similar triangles: R·d_ca/(d_lc + d_ca) for a parallel caster), and the disk of
// radius w around x, projected along the ray onto the plane, has radii w along X and
// w·|cos θ + (d·e2) sin θ/(n·d)| along e2; each at least half a caster texel (the square box of
// `Light` shape 2, and a sphere's fallback). A sphere's kernel is the ellipse its cone cuts from
// the plane (`sphere_ellipse`). A light that is not beyond the caster plane as seen from p (s
// outside [0, 1)) casts no caster shadow.
fn light_blur(p: vec2<f32>, l: Light, li: u32) -> vec4<f32> {
    let r = frame.caster_rect;
    let centre = vec3<f32>(0.5 * (r.xy + r.zw), frame.caster_height);
    let n = vec3<f32>(0.0, -frame.caster_sin_tilt, frame.caster_cos_tilt);
    let e2 = vec3<f32>(0.0, frame.caster_cos_tilt, frame.caster_sin_tilt);
    let pp = vec3<f32>(p, 0.0);
    var ray = l.position - pp;
    var beyond = 1.0;
//#if DISTANT
    // A distant light: along its unit direction (s is then a distance), always beyond. (A
    // test of the shape even with every light distant: a glossy lobe's imaginary light is a
    // point.)
    if (l.shape == LIGHT_DISTANT) {
        ray = l.position;
        beyond = 3.4e38;
    }
//#endif
    let denom = dot(n, ray);
    if (denom == 0.0) {
        return vec4<f32>(0.0);
    }
    let s = dot(n, centre - pp) / denom;
    if (!(s >= 0.0 && s < beyond)) {
        return vec4<f32>(0.0);
    }
    let off = pp + s * ray - centre;
    let q = centre.xy + vec2<f32>(off.x, dot(off, e2));
    let stretch = abs(frame.caster_cos_tilt + dot(ray, e2) * frame.caster_sin_tilt / denom);
    let texel = (r.zw - r.xy) / vec2<f32>(plane.size);
    let t = caster_texel_coords(q);
    if (l.shape == 1u) {
        // A rectangle facing down: its image from p on the plane is the rectangle scaled by s
        // (exactly, for a caster parallel to it), a box of half-sides s·half. Its patches light
        // p in proportion to cos·cos/r² = z²/r⁴, more on the side nearer p: to first order in
        // the half-sides the box moves to that weighting's centroid, −(4/3)·half²·d/r² on the
        // light (d = light − p across the cloth), s times that on the plane (rows run to −y).
        // Turned by θ (l.axis = (cos θ, sin θ)), the shift is found in the light's own frame
        // (side a along its first axis) and turned back.
        let a = l.axis;
        let dl = vec2<f32>(dot(ray.xy, a), a.x * ray.y - a.y * ray.x);
        let sl = -4.0 / (3.0 * dot(ray, ray)) * l.half * l.half * dl * s;
        let shift = sl.x * a + sl.y * vec2<f32>(-a.y, a.x);
        let tr = t + vec2<f32>(shift.x, -shift.y * stretch) / texel;
//#if RECT_TURNED
        if (a.y != 0.0) {
            // The turned rectangle's image: a parallelogram of half-edges e1, e2 in texels
            // (rows run to −y, a tilted caster stretches them).
            let e1 = vec2<f32>(a.x, -a.y * stretch) * (l.half.x * s) / texel;
            let e2 = vec2<f32>(-a.y, -a.x * stretch) * (l.half.y * s) / texel;
            return rect_slabs(li, tr, e1, e2);
        }
//#endif
        // Floored at 1/256 texel, not ½ as a sphere's: a thin light's kernel is a line, which
        // sees the texel it crosses, not the mean of two (the box stays exact down to there).
        let wr = max(vec2<f32>(l.half.x * s, l.half.y * s * stretch) / texel, vec2<f32>(RECT_MIN));
        return blur_lookup(li, tr, wr, 0.0, KERNEL_BOX);
    }
//#if GAUSSIAN
    if (l.shape == 3u) {
        // A Gaussian facing down (σ = half): as a rectangle, its image on the plane is itself
        // scaled by s, a Gaussian of σ·s, moved to the centroid of the z²/r⁴ weights, −4·σ²·d/r²
        // on the light to first order (a rectangle's −(4/3)·half² is −4 × its variance).
        let d = ray.xy;
        let shift = -4.0 / dot(ray, ray) * l.half * l.half * d * s;
        let tr = t + vec2<f32>(shift.x, -shift.y * stretch) / texel;
        let wr = max(vec2<f32>(l.half.x * s, l.half.y * s * stretch) / texel, vec2<f32>(RECT_MIN));
        return blur_lookup(li, tr, wr, 0.0, KERNEL_GAUSS);
    }
//#endif
    let w = l.radius * s;
    let wt = max(vec2<f32>(w, w * stretch) / texel, vec2<f32>(0.5));
    if (l.shape == 0u || l.shape == 4u || l.shape == LIGHT_DISTANT) {
        let e = sphere_ellipse(ray, s, l.radius, texel, l.shape == 4u);
        if (e.ok) {
            return blur_lookup(li, t + e.centre, e.radii, e.shear, KERNEL_DISC);
        }
    }
    return blur_lookup(li, t, wt, 0.0, KERNEL_BOX);
}

//#if RECT_TURNED
// The horizontal chord of a parallelogram centred at 0 at height y: (length, midpoint x). Its
// vertices are at heights ±top (the apexes, the upper one at x = apex_x) and ±inner; between
// ±inner the chord runs between two parallel edges (length `len`, midpoint y·slope), beyond it
// shrinks linearly to the apex.
fn rect_chord(y: f32, top: f32, inner: f32, len: f32, slope: f32, apex_x: f32) -> vec2<f32> {
    let ay = abs(y);
    if (ay <= inner) {
        return vec2<f32>(len, y * slope);
    }
    let f = (ay - inner) / (top - inner);
    let sg = sign(y);
    return vec2<f32>(len * (1.0 - f), mix(sg * inner * slope, sg * apex_x, f));
}

// A turned rectangle light's kernel: the parallelogram t + a·e1 + b·e2 (|a|, |b| ≤ 1, texels)
// averaged as boxes, one per horizontal band, each of the band's exact area (Simpson's rule in
// the chord, exact: the chord's length and midpoint are linear within a band) centred on its
// centroid. The bands: RECT_TRI across each corner triangle (between the apex and inner vertex
// heights) and, across the middle (between two parallel edges), enough that the chord's
// midpoint moves at most half its length within one (at most RECT_MID_MAX). Axis-aligned, the
// middle band is one exact box. The count depends on the shape (aspect and turn), not the size.
const RECT_TRI: u32 = 3u;
const RECT_MID_MAX: u32 = 16u;

fn rect_slabs(li: u32, t: vec2<f32>, e1: vec2<f32>, e2: vec2<f32>) -> vec4<f32> {
    let y1 = abs(e1.y);
    let y2 = abs(e2.y);
    let top = y1 + y2;
    let inner = abs(y1 - y2);
    let area = 4.0 * abs(e1.x * e2.y - e1.y * e2.x);
    if (!(top > RECT_MIN && area > 0.0)) {
        let w = vec2<f32>(abs(e1.x) + abs(e2.x), top);
        return blur_lookup(li, t, max(w, vec2<f32>(RECT_MIN)), 0.0, KERNEL_BOX);
    }
    let ea = select(e2, e1, y1 >= y2);
    let slope = ea.x / ea.y;
    let len = area / (top + inner);
    let apex_x = select(-1.0, 1.0, e1.y >= 0.0) * e1.x + select(-1.0, 1.0, e2.y >= 0.0) * e2.x;
    let shear = 2.0 * inner * abs(slope) / (0.5 * len);
    let n_mid = u32(clamp(ceil(shear), 1.0, f32(RECT_MID_MAX)));
    let tri = (top - inner) / f32(RECT_TRI);
    let mid = 2.0 * inner / f32(n_mid);
    var sum = vec4<f32>(0.0);
    var total = 0.0;
    for (var k = 0u; k < 2u * RECT_TRI + n_mid; k++) {
        var y0 = -top + f32(k) * tri;
        var h = tri;
        if (k >= RECT_TRI + n_mid) {
            y0 = inner + f32(k - RECT_TRI - n_mid) * tri;
        } else if (k >= RECT_TRI) {
            y0 = -inner + f32(k - RECT_TRI) * mid;
            h = mid;
        }
        if (!(h > 0.0)) {
            continue;
        }
        let c0 = rect_chord(y0, top, inner, len, slope, apex_x);
        let cm = rect_chord(y0 + 0.5 * h, top, inner, len, slope, apex_x);
        let c1 = rect_chord(y0 + h, top, inner, len, slope, apex_x);
        let w = h / 6.0 * (c0.x + 4.0 * cm.x + c1.x);
        if (!(w > 0.0)) {
            continue;
        }
        let cx = h / 6.0 * (c0.x * c0.y + 4.0 * cm.x * cm.y + c1.x * c1.y) / w;
        let half = max(vec2<f32>(0.5 * w / h, 0.5 * h), vec2<f32>(RECT_MIN));
        sum += w * blur_lookup(li, t + vec2<f32>(cx, y0 + 0.5 * h), half, 0.0, KERNEL_BOX);
        total += w;
    }
    return sum / total;
}
//#endif

// The caster's opacity towards light l at p (per channel): `light_blur`'s image mean, whose
// opacity is α in a glossy scene's premultiplied image (its fourth channel).
fn light_opacity(p: vec2<f32>, l: Light, li: u32) -> vec3<f32> {
    let o = light_blur(p, l, li);
//#if GLOSSY
    return vec3<f32>(o.w);
//#else
    return o.xyz;
//#endif
}

// The ellipse a sphere's cone cuts from the caster plane, in caster texels: centre offset from
// the axis's hit point t, radii (half-width of the chord through the centre along the rows,
// half-height) and shear (the chords' midpoints move `shear` texels across per texel down):
// ((x − shear·y)/radii.x)² + (y/radii.y)² ≤ 1, each radius at least ½ texel.
// Derivation: apex p, axis a = ray/D, sin²α = σ² = R²/D². With the in-plane axes X and e2 and
// origin at the axis's hit s·ray, a plane point x = u·X + v·e2 is in the cone when
// |x⊥|² ≤ σ²|s·ray + x|² (⊥: across a), i.e. xᵀMx − 2bᵀx ≤ k with M = G − σ²I,
// G = I − (a·X, a·e2)(a·X, a·e2)ᵀ, b = σ²·s·(ray·X, ray·e2), k = σ²s²D²: centre x0 = M⁻¹b,
// (x − x0)ᵀM(x − x0) ≤ g = k + b·x0. M is positive definite while (a·n)² > σ² (the cone
// meets the plane in a closed curve); `ok` is false otherwise. Everything is a sum of
// positive terms or of σ²-sized ones, so f32 keeps small lights accurate.
struct Ellipse {
    centre: vec2<f32>,
    radii: vec2<f32>,
    shear: f32,
    ok: bool,
}

fn sphere_ellipse(ray: vec3<f32>, s: f32, radius: f32, texel: vec2<f32>, lobe: bool) -> Ellipse {
    var e: Ellipse;
    e.ok = false;
    let d2 = dot(ray, ray);
    let a = ray / sqrt(d2);
    let sigma2 = radius * radius / d2;
    let ax = a.x;
    let a2 = a.y * frame.caster_cos_tilt + a.z * frame.caster_sin_tilt;
    let an = -a.y * frame.caster_sin_tilt + a.z * frame.caster_cos_tilt;
    if (!(an * an > 1.0001 * sigma2)) {
        return e;
    }
    // 1 − (a·X)² and 1 − (a·e2)², as sums of squares.
    let m00 = a.y * a.y + a.z * a.z - sigma2;
    let m01 = -ax * a2;
    let m11 = ax * ax + an * an - sigma2;
    let det = m00 * m11 - m01 * m01;
    let b = sigma2 * s * vec2<f32>(ray.x, ray.y * frame.caster_cos_tilt + ray.z * frame.caster_sin_tilt);
    let x0 = vec2<f32>(m11 * b.x - m01 * b.y, m00 * b.y - m01 * b.x) / det;
    let g = sigma2 * s * s * d2 + dot(b, x0);
    if (!(g > 0.0 && det > 0.0)) {
        return e;
    }
    // Texel axes: u/texel.x across, −v/texel.y down.
    let radii = vec2<f32>(sqrt(g / m00) / texel.x, sqrt(m00 * g / det) / texel.y);
    e.shear = m01 * texel.y / (m00 * texel.x);
    // The light's directions are not spread evenly over the ellipse: per unit of plane area they
    // weigh (cos at p)·(solid angle) = (y.z/|y|)·|n·y|/|y|³ at y = plane point − p, more on
    // the near side. Moving the ellipse to that weight's centroid, to first order
    // Σ·∇ln(weight) with Σ = L·Lᵀ/4 its covariance (L = [[rx, shear·ry], [0, ry]]), matches
    // the weighted mean; ∇ln(weight) along an in-plane unit e is e.z/y.z − 4(y·e)/|y|². The
    // move is capped at half the radii (before the ½-texel floor).
    let e2 = vec3<f32>(0.0, frame.caster_cos_tilt, frame.caster_sin_tilt);
    let y = s * ray + vec3<f32>(x0.x, 0.0, 0.0) + x0.y * e2;
    let yy = dot(y, y);
    // A glossy lobe (`lobe`) is uniform in solid angle alone, |n·y|/|y|³ (n·y the same over the
    // plane): ∇ln = −3(y·e)/|y|², no cos at p.
    var grad = vec2<f32>(-4.0 * y.x / yy * texel.x, -(e2.z / y.z - 4.0 * dot(y, e2) / yy) * texel.y);
    if (lobe) {
        grad = vec2<f32>(-3.0 * y.x / yy * texel.x, 3.0 * dot(y, e2) / yy * texel.y);
    }
    let rx = radii.x;
    let ry = radii.y;
    let sxx = 0.25 * (rx * rx + e.shear * e.shear * ry * ry);
    let sxy = 0.25 * e.shear * ry * ry;
    let syy = 0.25 * ry * ry;
    let shift = vec2<f32>(sxx * grad.x + sxy * grad.y, sxy * grad.x + syy * grad.y);
    let v = shift.y / ry;
    let u = (shift.x - e.shear * shift.y) / rx;
    let k = min(1.0, 0.5 / max(sqrt(u * u + v * v), 1e-20));
    e.centre = vec2<f32>(x0.x / texel.x, -x0.y / texel.y) + k * shift;
    e.radii = max(radii, vec2<f32>(0.5));
    e.ok = true;
    return e;
}

// The kernel `blur_lookup` is asked for (`blur::Kernel` as a number): the sheared ellipse of
// radii wt ((x − shear·y)/wt.x)² + (y/wt.y)² ≤ 1 (a sphere's), the box of half-sides wt (a
// rectangle's, shear 0), or the Gaussian of standard deviations wt (a Gaussian light's, shear
// 0). A method approximates what it cannot apply exactly (`blur::Method::kernels`).
const KERNEL_DISC: u32 = 0u;
const KERNEL_BOX: u32 = 1u;
//#if GAUSSIAN
const KERNEL_GAUSS: u32 = 2u;
//#endif

// The least half-side of a rectangle's box, in texels (`cpu::shade::RECT_MIN`).
const RECT_MIN: f32 = 0.00390625;

// The blur method's WGSL (`blur::Method::wgsl`): its bindings and `blur_lookup`.
{{BLUR}}
//#endif

//#if GLOSSY
// Glossy receiver (`scene::Glossy`): the radiance reflected at cloth point p seen along the unit
// view direction `dir` (towards the cloth). The lobe is a cone of half-angle α around the mirror
// direction r; it meets the (tilted) caster plane at distance h along r. The "imaginary light"
// is the sphere on r at 2h whose radius 2h·sin α subtends that cone from p, so the caster is
// blurred exactly as for its shadow (`light_blur`: the cone's ellipse on the plane, half-way
// to the light), by an amount growing linearly with h. The image holds premultiplied linear
// colour and opacity (α·rgb, α), so each texel reflects its own colour: mean(α·rgb) +
// (1 − mean α)·background; where the kernel runs off the caster its texels count as
// transparent and the background shows. A lobe
// that never meets the plane reflects the background alone.
fn glossy_reflection(p: vec2<f32>, dir: vec3<f32>) -> vec3<f32> {
    let r = vec3<f32>(dir.xy, -dir.z);
    var back = frame.glossy_background;
//#if GLOSSY_ENV
    back = env_lookup(r);
//#endif
    let c = frame.caster_rect;
    let centre = vec3<f32>(0.5 * (c.xy + c.zw), frame.caster_height);
    let n = vec3<f32>(0.0, -frame.caster_sin_tilt, frame.caster_cos_tilt);
    let pp = vec3<f32>(p, 0.0);
    let denom = dot(n, r);
    if (!(denom > 0.0)) {
        return back;
    }
    let h = dot(n, centre - pp) / denom;
    if (!(h > 0.0)) {
        return back;
    }
    var l: Light;
    l.position = pp + 2.0 * h * r;
    l.radius = 0.0; // per cone below
    l.color = vec3<f32>(0.0);
    l.shape = 4u;
    l.half = vec2<f32>(0.0);
    l.axis = vec2<f32>(1.0, 0.0);
    // A wide lobe as nested cones (`glossy_rings`): the kernel is uniform over each cone's
    // ellipse by area, the lobe uniform in solid angle, which per unit of plane area falls off
    // as 1/distance³ away from the axis. The cones' weights c_j give every ring between two
    // of them its exact solid angle (`glossy_ring_weights`).
    let rings = glossy_ring_weights(denom);
    var o = vec4<f32>(0.0);
    for (var j = 0u; j < frame.glossy_rings; j++) {
        let w = rings[j];
        if (w > 0.0) {
            let a = frame.glossy_alpha * f32(j + 1u) / f32(frame.glossy_rings);
            l.radius = 2.0 * h * sin(a);
            o += w * max(light_blur(p, l, 0u), vec4<f32>(0.0));
        }
    }
    return o.xyz + back * (1.0 - min(o.w, 1.0));
}

// The weights of the nested cones of half-angles α_j = α·j/N (j = 1 … N = `glossy_rings`)
// whose uniform-area ellipses on the caster plane, mixed, put on every ring between cones
// j − 1 and j the lobe's exact share of solid angle (Ω_j − Ω_{j−1})/Ω_N. With A_j the ellipse
// areas, the mixture's density on ring i is Σ_{j≥i} c_j/A_j; setting it to the ring's
// d_i = ΔΩ_i/(Ω_N·ΔA_i) gives c_j = A_j·(d_j − d_{j+1}). A cone of half-angle a whose axis is
// β off the plane's normal (cos β = `cos_b`) cuts an ellipse of area ∝ sin²a·cos a/(cos²β −
// sin²a)^{3/2}; Ω ∝ 1 − cos a = 2 sin²(a/2). One cone (weight 1) where N = 1 or the widest
// cone does not close on the plane.
fn glossy_ring_weights(cos_b: f32) -> array<f32, 4> {
    var c = array<f32, 4>(1.0, 0.0, 0.0, 0.0);
    let n = frame.glossy_rings;
    if (n <= 1u) {
        return c;
    }
    var area = array<f32, 5>(0.0, 0.0, 0.0, 0.0, 0.0);
    var omega = array<f32, 5>(0.0, 0.0, 0.0, 0.0, 0.0);
    for (var j = 1u; j <= n; j++) {
        let a = frame.glossy_alpha * f32(j) / f32(n);
        let s = sin(a);
        let q = cos_b * cos_b - s * s;
        if (!(q > 0.0)) {
            return c;
        }
        area[j] = s * s * cos(a) / (q * sqrt(q));
        let half = sin(0.5 * a);
        omega[j] = 2.0 * half * half;
    }
    var d = array<f32, 5>(0.0, 0.0, 0.0, 0.0, 0.0);
    for (var i = 1u; i <= n; i++) {
        d[i - 1u] = (omega[i] - omega[i - 1u]) / (omega[n] * (area[i] - area[i - 1u]));
    }
    var total = 0.0;
    for (var j = 0u; j < n; j++) {
        let next = select(0.0, d[j + 1u], j + 1u < n);
        c[j] = max(area[j + 1u] * (d[j] - next), 0.0);
        total += c[j];
    }
    if (!(total > 0.0)) {
        return array<f32, 4>(1.0, 0.0, 0.0, 0.0);
    }
    for (var j = 0u; j < n; j++) {
        c[j] = c[j] / total;
    }
    return c;
}

//#if GLOSSY_ENV
// The background image (`environment.rs`): the upper hemisphere as an equal-area map, N × N
// over [−1, 1]², prefiltered on the CPU for this scene's lobe (each texel the sky averaged
// over the cone around its direction).
const ENV_SIZE: u32 = {{ENV_SIZE}}u;
@group(0) @binding(16) var<storage, read> environment: array<vec4<f32>>;

fn env_texel(x: i32, y: i32) -> vec4<f32> {
    let s = i32(ENV_SIZE);
    return environment[u32(clamp(y, 0, s - 1) * s + clamp(x, 0, s - 1))];
}

// Bilinear read at texel coordinate t, clamped to the edge.
fn env_bilinear(t: vec2<f32>) -> vec4<f32> {
    let c = t - 0.5;
    let c0 = floor(c);
    let a = c - c0;
    let x = i32(c0.x);
    let y = i32(c0.y);
    return mix(
        mix(env_texel(x, y), env_texel(x + 1, y), a.x),
        mix(env_texel(x, y + 1), env_texel(x + 1, y + 1), a.x),
        a.y,
    );
}

// The background along the mirror direction r (r.z ≥ 0): (u, v) = r.xy/√(1 + r.z).
fn env_lookup(r: vec3<f32>) -> vec3<f32> {
    let uv = r.xy * (1.0 / sqrt(1.0 + r.z));
    return env_bilinear((uv + 1.0) * (0.5 * f32(ENV_SIZE))).xyz;
}
//#endif

// Schlick's Fresnel at the view direction's angle to the normal +Z.
fn glossy_fresnel(dir: vec3<f32>) -> f32 {
    let m = 1.0 - clamp(-dir.z, 0.0, 1.0);
    return frame.glossy_f0 + (1.0 - frame.glossy_f0) * m * m * m * m * m;
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
//#if DISTANT_ONLY
        // Every light is distant: its unit direction, the same everywhere, and no falloff.
        let to_light = light.position;
        let d2 = 1.0;
//#else
        var to_light = vec3<f32>(light.position.xy - p, light.position.z);
        var d2 = dot(to_light, to_light);
//#if DISTANT
        // A distant light: its unit direction, the same everywhere, and no falloff.
        if (light.shape == LIGHT_DISTANT) {
            to_light = light.position;
            d2 = 1.0;
        }
//#endif
//#endif
        if (d2 <= 0.0 || to_light.z <= 0.0) {
            continue;
        }
        let l = to_light / sqrt(d2);
        var visible = vec3<f32>(1.0);
//#if PTM
//#if DISTANT_ONLY
        // (No local light: no branch between the two paths.)
        visible *= 1.0 - distant_k(c, i);
//#else
//#if DISTANT
        if (light.shape == LIGHT_DISTANT) {
            visible *= 1.0 - distant_k(c, i);
        } else {
            visible *= 1.0 - ptm_k_area(c, l, ptm_footprint(l, to_light, sqrt(d2), light));
        }
//#else
        visible *= 1.0 - ptm_k_area(c, l, ptm_footprint(l, to_light, sqrt(d2), light));
//#endif
//#endif
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

//#if MESH
{{MESH}}
//#else
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
//#if GLOSSY
    var dir = vec3<f32>(0.0, 0.0, -1.0);
    if (frame.perspective != 0u) {
        dir = normalize(view_dir(frag.xy));
    }
    let fresnel = glossy_fresnel(dir);
    let glossy = glossy_reflection(p.xy, dir);
    return vec4<f32>((1.0 - fresnel) * shade(p.xy, lod) + fresnel * glossy, 1.0);
//#else
    return vec4<f32>(shade(p.xy, lod), 1.0);
//#endif
}
//#endif
