// mesh.wgsl: the mesh path (`ptm preview --mesh`), included into shade.wgsl in place of its
// full-screen triangle for MESH variants: a vertex stage that projects the mesh with the
// perspective camera, and a fragment stage that evaluates K in each pixel's tangent frame with
// shade.wgsl's own PTM lookups (ptm_coeffs, ptm_k, ptm_coverage, albedo_at) and shades
// Lambert + the glTF KHR_materials_sheen lobe. The CPU twin is cpu/mesh.rs (same names, same
// maths, a software rasteriser in place of the GPU's).

struct MeshIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    @location(4) uv_scale: f32,
}

struct MeshOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    @location(4) uv_scale: f32,
}

const PI: f32 = 3.141592653589793;

// Clip coordinates of world point q for the perspective camera of shade.wgsl's view_dir: the
// ray eye + s·dir through the pixel at ndc (x, y) has dir = forward + x·right + y·up, so
// x = (d·right)/|right|² / s and y likewise, with s = d·forward (w); depth runs 0 at `near` to 1
// at `far`.
fn mesh_clip(q: vec3<f32>) -> vec4<f32> {
    let d = q - frame.eye;
    let w = dot(d, frame.cam_forward);
    let x = dot(d, frame.cam_right) / dot(frame.cam_right, frame.cam_right);
    let y = dot(d, frame.cam_up) / dot(frame.cam_up, frame.cam_up);
    let z = (w - frame.near) * frame.far / (frame.far - frame.near);
    return vec4<f32>(x, y, z, w);
}

//#if SHADOW
// The mesh's macro shadow: one depth map per light (layer i for light i), rendered from the
// light's centre by vs_shadow before the shading pass, read by shadow_visibility (PCSS: a
// blocker search, then percentage-closer filtering over the light's penumbra).
@group(0) @binding(14) var shadow_maps: texture_depth_2d_array;
// Nearest, clamped: shadow_taps gathers a 2×2 block of depths with it (no filtering).
@group(0) @binding(15) var shadow_sampler: sampler;

// The perspective view a light's shadow map is rendered with: from the light's centre towards
// the centre of the box (frame.shadow_lo … shadow_hi) that bounds the mesh, the square frustum
// through the box's outermost corner (right and up scaled by the tangent of its half-angle, as
// the camera's are), near and far planes just around the box's nearest and farthest corners.
// A light inside the box or beside it (a corner at or behind it, or more than
// SHADOW_MAX_TAN off the axis) gets the widest frustum, SHADOW_MAX_TAN, and a near plane at
// 1/1000 of the box's diagonal: what lies outside casts and receives no macro shadow. `ok` is
// false only for a light at the box's centre.
struct ShadowView {
    right: vec3<f32>,
    up: vec3<f32>,
    forward: vec3<f32>,
    near: f32,
    far: f32,
    ok: bool,
    // A distant light's view (`shadow_view_ortho`): parallel rays, right and up scaled by the
    // half-extent instead of a tangent, depths linear in the forward distance.
    ortho: bool,
}

// tan 76°: the widest half-angle of a shadow map.
const SHADOW_MAX_TAN: f32 = 4.0;

// A shadow view's unit right and up axes across the unit forward direction f (up from the
// world's Z, or Y when f is nearly vertical).
fn shadow_axes(f: vec3<f32>) -> array<vec3<f32>, 2> {
    var world_up = vec3<f32>(0.0, 0.0, 1.0);
    if (abs(f.z) > 0.999) {
        world_up = vec3<f32>(0.0, 1.0, 0.0);
    }
    let right = normalize(cross(f, world_up));
    return array<vec3<f32>, 2>(right, cross(right, f));
}

fn shadow_view(lp: vec3<f32>) -> ShadowView {
    var s: ShadowView;
    let lo = frame.shadow_lo;
    let hi = frame.shadow_hi;
    let to_c = 0.5 * (lo + hi) - lp;
    let d = length(to_c);
    let diag = length(hi - lo);
    s.ok = d > 1e-6 * diag;
    if (!s.ok) {
        return s;
    }
    let f = to_c / d;
    let axes = shadow_axes(f);
    let right = axes[0];
    let up = axes[1];
    var t = 0.0;
    var near = 3.4e38;
    var far = 0.0;
    for (var k = 0u; k < 8u; k++) {
        let q = select(lo, hi, vec3<bool>((k & 1u) != 0u, (k & 2u) != 0u, (k & 4u) != 0u));
        let v = q - lp;
        let w = dot(v, f);
        near = min(near, w);
        far = max(far, w);
        t = max(t, max(abs(dot(v, right)), abs(dot(v, up))) / max(w, 1e-30));
    }
    let eps = 1e-3 * diag;
    s.right = right * min(t, SHADOW_MAX_TAN);
    s.up = up * min(t, SHADOW_MAX_TAN);
    s.forward = f;
    s.near = max(0.99 * near, eps);
    s.far = max(1.01 * far, s.near + eps);
    return s;
}

// Clip coordinates of world point q in the shadow view of the light at lp (mesh_clip's maths).
fn shadow_clip(sv: ShadowView, lp: vec3<f32>, q: vec3<f32>) -> vec4<f32> {
    let d = q - lp;
    let w = dot(d, sv.forward);
    let x = dot(d, sv.right) / dot(sv.right, sv.right);
    let y = dot(d, sv.up) / dot(sv.up, sv.up);
//#if MESH_DISTANT
    if (sv.ortho) {
        return vec4<f32>(x, y, (w - sv.near) / (sv.far - sv.near), 1.0);
    }
//#endif
    let z = (w - sv.near) * sv.far / (sv.far - sv.near);
    return vec4<f32>(x, y, z, w);
}

//#if MESH_DISTANT
// A distant light's shadow view: orthographic along its direction, from the box's centre, the
// square that bounds the box's corners across it, near and far planes just around them.
fn shadow_view_ortho(dir: vec3<f32>) -> ShadowView {
    var s: ShadowView;
    let lo = frame.shadow_lo;
    let hi = frame.shadow_hi;
    let c = 0.5 * (lo + hi);
    let diag = length(hi - lo);
    let f = -dir;
    let axes = shadow_axes(f);
    let right = axes[0];
    let up = axes[1];
    var h = 0.0;
    var near = 3.4e38;
    var far = -3.4e38;
    for (var k = 0u; k < 8u; k++) {
        let q = select(lo, hi, vec3<bool>((k & 1u) != 0u, (k & 2u) != 0u, (k & 4u) != 0u));
        let v = q - c;
        let w = dot(v, f);
        near = min(near, w);
        far = max(far, w);
        h = max(h, max(abs(dot(v, right)), abs(dot(v, up))));
    }
    let eps = 1e-3 * diag;
    s.ok = diag > 0.0;
    s.ortho = true;
    s.right = right * max(1.01 * h, eps);
    s.up = up * max(1.01 * h, eps);
    s.forward = f;
    s.near = near - eps;
    s.far = far + eps;
    return s;
}
//#endif

// Light `l`'s shadow view: the perspective one from its centre, or a distant light's
// orthographic one.
fn light_shadow_view(l: Light) -> ShadowView {
//#if MESH_DISTANT
    if (l.shape == LIGHT_DISTANT) {
        return shadow_view_ortho(l.position);
    }
//#endif
    return shadow_view(l.position);
}

// Where light `l`'s shadow view starts (xyz) and how its disc spreads (w): a local light's
// centre and the radius `shadow_light_radius`; a distant light's view is centred on the box,
// and its cone widens by tan ρ per unit of distance.
fn shadow_source(l: Light) -> vec4<f32> {
//#if MESH_DISTANT
    if (l.shape == LIGHT_DISTANT) {
        let tan_rho = l.radius / sqrt(max(1.0 - l.radius * l.radius, 1e-12));
        return vec4<f32>(0.5 * (frame.shadow_lo + frame.shadow_hi), tan_rho);
    }
//#endif
    return vec4<f32>(l.position, shadow_light_radius(l));
}

// The depth pass: the mesh seen from light `li` (the draw's instance), into layer li.
@vertex
fn vs_shadow(v: MeshIn, @builtin(instance_index) li: u32) -> @builtin(position) vec4<f32> {
    let lp = shadow_source(lights[li]).xyz;
    let sv = light_shadow_view(lights[li]);
    if (!sv.ok) {
        return vec4<f32>(0.0, 0.0, -1.0, 1.0); // clipped: the layer stays clear
    }
    return shadow_clip(sv, lp, v.position);
}

// Forward distance from the light of a stored depth (the inverse of shadow_clip's z/w; a clear
// texel, 1, is the far plane: never a blocker).
fn shadow_distance(sv: ShadowView, z: f32) -> f32 {
//#if MESH_DISTANT
    if (sv.ortho) {
        return sv.near + z * (sv.far - sv.near);
    }
//#endif
    return sv.near * sv.far / (sv.far - z * (sv.far - sv.near));
}

// The stored depth z/w of forward distance w (shadow_clip's): taps compare depths, so only a
// blocker's depth is turned back into a distance.
fn shadow_depth(sv: ShadowView, w: f32) -> f32 {
//#if MESH_DISTANT
    if (sv.ortho) {
        return (w - sv.near) / (sv.far - sv.near);
    }
//#endif
    return (w - sv.near) * sv.far / ((sv.far - sv.near) * w);
}

// The 2×2 texels of layer li around continuous texel coordinates t (texel centres at i + ½,
// row 0 at the top of the light's view), bilinearly weighted: (weight of those nearer the light
// than depth zr, weighted sum of their distances). Outside the map nothing is stored: no
// blocker.
fn shadow_taps(li: u32, sv: ShadowView, t: vec2<f32>, zr: f32) -> vec2<f32> {
    let n = i32(frame.shadow_size);
    let c = t - 0.5;
    let c0 = floor(c);
    let a = c - c0;
    let i0 = vec2<i32>(c0);
    // The block's shared corner, half a texel from every texel centre: the gather takes exactly
    // texels i0 … i0 + 1 there (x: (x0, y1), y: (x1, y1), z: (x1, y0), w: (x0, y0)).
    let g = textureGather(shadow_maps, shadow_sampler, (c0 + 1.0) / f32(n), i32(li));
    var depths = array<f32, 4>(g.w, g.z, g.x, g.y);
    var blocked = 0.0;
    var dist = 0.0;
    for (var k = 0; k < 4; k++) {
        let o = vec2<i32>(k & 1, k >> 1u);
        let q = i0 + o;
        if (q.x < 0 || q.y < 0 || q.x >= n || q.y >= n) {
            continue;
        }
        let wx = select(1.0 - a.x, a.x, o.x == 1);
        let wy = select(1.0 - a.y, a.y, o.y == 1);
        let z = depths[k];
        if (z < zr) {
            blocked += wx * wy;
            dist += wx * wy * shadow_distance(sv, z);
        }
    }
    return vec2<f32>(blocked, dist);
}

// The fixed sample pattern of both PCSS steps: a Vogel disc of 16 points in the unit disc
// (radius √((k + ½)/16), angle k × the golden angle), the same f32 literals in the twin.
const SHADOW_SAMPLES: u32 = 16u;
const SHADOW_DISC: array<vec2<f32>, 16> = array<vec2<f32>, 16>(
    vec2<f32>(0.17677669, 0.0),
    vec2<f32>(-0.22577219, 0.20682582),
    vec2<f32>(0.03455805, -0.39377117),
    vec2<f32>(0.28457123, 0.37117276),
    vec2<f32>(-0.5222232, -0.09237393),
    vec2<f32>(0.4946954, -0.31468472),
    vec2<f32>(-0.16546592, 0.615525),
    vec2<f32>(-0.31556147, -0.60759443),
    vec2<f32>(0.68464214, 0.25003022),
    vec2<f32>(-0.7122561, 0.29400897),
    vec2<f32>(0.3433545, -0.73372865),
    vec2<f32>(0.25373024, 0.808932),
    vec2<f32>(-0.7647459, -0.44318587),
    vec2<f32>(0.897134, -0.1972324),
    vec2<f32>(-0.5475069, 0.77877223),
    vec2<f32>(-0.12648678, -0.9760897),
);

// Bias, in texel footprints at the receiver (a texel's width there, 2·tan(half-angle)·w/size):
// the point looked up is moved this far off the surface towards the light, and a blocker must
// be nearer the light than the moved point by SHADOW_BIAS footprints.
const SHADOW_NORMAL_OFFSET: f32 = 1.0;
const SHADOW_BIAS: f32 = 1.5;

// Radius of the disc a light is filtered as: a sphere's radius, a rectangle's equal-area disc,
// a Gaussian's disc of the same variance (r²/4 = σx·σy).
fn shadow_light_radius(l: Light) -> f32 {
    if (l.shape == 1u) {
        return sqrt(4.0 * l.half.x * l.half.y / PI);
    }
//#if GAUSSIAN
    if (l.shape == 3u) {
        return 2.0 * sqrt(l.half.x * l.half.y);
    }
//#endif
    return l.radius;
}

// Fraction of light li's disc that the mesh leaves visible from surface point `world` of unit
// normal n (turned to the light's side): percentage-closer soft shadows (Fernando 2005) with the
// penumbra map's similar triangles. A lateral length ℓ at forward distance D spans
// ℓ/(D·tan)·size/2 texels. Blockers are searched where the cone from the point to the light's
// disc crosses the near plane; their mean distance wb gives the penumbra on the map,
// R·(wr − wb)/(wr·wb) in the same units (the cone's radius at the blockers, seen from the
// light), over which the depth comparisons are averaged (bilinear PCF at each sample; both radii
// capped at size/16 texels). No search tap blocked: lit; every one: the umbra. A point light
// (R = 0) gets a hard shadow, filtered over one texel.
fn shadow_visibility(li: u32, world: vec3<f32>, n: vec3<f32>) -> f32 {
    let light = lights[li];
    let source = shadow_source(light);
    let lp = source.xyz;
    let sv = light_shadow_view(light);
    if (!sv.ok) {
        return 1.0;
    }
    let size = f32(frame.shadow_size);
    let tan_half = length(sv.right);
    var footprint = 2.0 * tan_half * dot(world - lp, sv.forward) / size;
//#if MESH_DISTANT
    // Orthographic: a texel spans the same length at every distance (tan_half is then the
    // half-extent), a lateral length ℓ spans ℓ·size/(2·half) texels, and the cone from a point
    // to a distant light widens by tan ρ (`source.w`) per unit of distance, so the radii below
    // lose their 1/(wr·near) and 1/(wr·wb).
    if (sv.ortho) {
        footprint = 2.0 * tan_half / size;
    }
//#endif
    let moved = world + n * (SHADOW_NORMAL_OFFSET * footprint);
    let clip = shadow_clip(sv, lp, moved);
    var fwd = clip.w;
//#if MESH_DISTANT
    if (sv.ortho) {
        fwd = dot(moved - lp, sv.forward);
    }
//#endif
    let wr = fwd - SHADOW_BIAS * footprint;
    let zr = shadow_depth(sv, wr);
    let t = vec2<f32>(clip.x / clip.w + 1.0, 1.0 - clip.y / clip.w) * (0.5 * size);
    let scale = 0.5 * size / tan_half;
    let cap = size / 16.0;
    let radius = source.w;
    var search = radius * max(wr - sv.near, 0.0) / (wr * sv.near) * scale;
//#if MESH_DISTANT
    if (sv.ortho) {
        search = radius * max(wr - sv.near, 0.0) * scale;
    }
//#endif
    search = min(search, cap);
    // A local copy: indexed by a loop counter, the array needs an address.
    var disc = SHADOW_DISC;
    var blocked = 0.0;
    var dist = 0.0;
    for (var k = 0u; k < SHADOW_SAMPLES; k++) {
        let b = shadow_taps(li, sv, t + disc[k] * search, zr);
        blocked += b.x;
        dist += b.y;
    }
    if (blocked <= 0.0) {
        return 1.0;
    }
    // Every search tap blocked: the penumbra's disc (never wider than the search's) is too.
    if (blocked > f32(SHADOW_SAMPLES) - 1e-3) {
        return 0.0;
    }
    let wb = dist / blocked;
    var penumbra = radius * max(wr - wb, 0.0) / (wr * wb) * scale;
//#if MESH_DISTANT
    if (sv.ortho) {
        penumbra = radius * max(wr - wb, 0.0) * scale;
    }
//#endif
    penumbra = min(penumbra, cap);
    var occluded = 0.0;
    for (var k = 0u; k < SHADOW_SAMPLES; k++) {
        occluded += shadow_taps(li, sv, t + disc[k] * penumbra, zr).x;
    }
    return 1.0 - occluded / f32(SHADOW_SAMPLES);
}
//#endif

@vertex
fn vs_mesh(v: MeshIn) -> MeshOut {
    var o: MeshOut;
    o.clip = mesh_clip(v.position);
    o.world = v.position;
    o.normal = v.normal;
    o.tangent = v.tangent;
    o.uv = v.uv;
    o.uv_scale = v.uv_scale;
    return o;
}

//#if PTM_MIP
// Level of detail at a surface point of normal n: shade.wgsl's ptm_lod generalised. The ray
// eye + s·dir (dir's forward component 1) reaches the point at s = d·forward; a pixel spans
// s·δ across the ray and s·δ·|dir|/|n·dir| along the surface's steepest direction, × the
// triangle's PTM units per mesh unit. On the plane z = 0 (n = +Z, uv_scale 1) this is ptm_lod's
// texels·eye.z·|dir|/dir.z².
fn mesh_lod(world: vec3<f32>, n: vec3<f32>, uv_scale: f32) -> f32 {
    let d = world - frame.eye;
    let s = dot(d, frame.cam_forward);
    let dir = d / s;
    let texels = frame.ptm_texels_per_pixel * uv_scale * s * length(dir)
        / max(abs(dot(n, dir)), 1e-6);
    return clamp(log2(max(texels, 1.0)), 0.0, f32(frame.ptm_level_count) - 1.0);
}
//#endif

// The tangent frame (T, B, N) of interpolated normal and tangent: N normalised, T made
// perpendicular to it (Gram–Schmidt), B = w · N × T (MikkTSpace's bitangent sign), N turned
// over where the back of the cloth is seen (a back-facing triangle: cloth is two-sided; B
// follows, keeping the frame right-handed).
fn tangent_frame(front: bool, normal: vec3<f32>, tangent: vec4<f32>) -> mat3x3<f32> {
    var n = normalize(normal);
    let t = normalize(tangent.xyz - n * dot(n, tangent.xyz));
    if (!front) {
        n = -n;
    }
    let b = tangent.w * cross(n, t);
    return mat3x3<f32>(t, b, n);
}

// The shading normal: the normal map's tangent-space normal brought into the frame, or N.
fn normal_at(p: vec2<f32>, tbn: mat3x3<f32>) -> vec3<f32> {
//#if NORMAL_MAP
    let b = tile_bilinear(p, frame.normal_size);
    let m = (b.weight.x * normal_tex[b.index.x] + b.weight.y * normal_tex[b.index.y]
        + b.weight.z * normal_tex[b.index.z] + b.weight.w * normal_tex[b.index.w]).xyz;
    return normalize(tbn * m);
//#else
    return tbn[2];
//#endif
}

// KHR_materials_sheen's Charlie distribution (Estevez & Kulla 2017), α = sheenRoughness²:
// D = (2 + 1/α) · sin(θh)^(1/α) / (2π).
fn sheen_d(alpha: f32, n_h: f32) -> f32 {
    let inv = 1.0 / alpha;
    let sin2 = max(1.0 - n_h * n_h, 0.0);
    return (2.0 + inv) * pow(sin2, 0.5 * inv) / (2.0 * PI);
}

// The fitted curve L(x) of the Charlie visibility's Λ (KHR_materials_sheen), its five
// coefficients interpolated by (1 − α)².
fn sheen_l(x: f32, alpha: f32) -> f32 {
    let t = (1.0 - alpha) * (1.0 - alpha);
    let a = mix(21.5473, 25.3245, t);
    let b = mix(3.82987, 3.32435, t);
    let c = mix(0.19823, 0.16801, t);
    let d = mix(-1.97760, -1.27393, t);
    let e = mix(-4.32054, -4.85967, t);
    return a / (1.0 + b * pow(x, c)) + d * x + e;
}

// Λ(cos θ) = e^L(cos θ) below 0.5, e^(2 L(0.5) − L(1 − cos θ)) above.
fn sheen_lambda(cos_theta: f32, alpha: f32) -> f32 {
    if (cos_theta < 0.5) {
        return exp(sheen_l(cos_theta, alpha));
    }
    return exp(2.0 * sheen_l(0.5, alpha) - sheen_l(1.0 - cos_theta, alpha));
}

// V = 1 / ((1 + Λ(n·v) + Λ(n·l)) · 4 (n·v)(n·l)), clamped to [0, 1] as the glTF sample
// viewer does.
fn sheen_visibility(n_l: f32, n_v: f32, alpha: f32) -> f32 {
    let denom = (1.0 + sheen_lambda(n_v, alpha) + sheen_lambda(n_l, alpha)) * (4.0 * n_v * n_l);
    return clamp(1.0 / denom, 0.0, 1.0);
}

// π · f_sheen = π · sheenColor · D · V: scaled by π as the Lambert term here is the albedo
// itself (the plane path's convention, π · albedo/π), so the two keep glTF's proportions.
fn sheen_brdf(n: vec3<f32>, v: vec3<f32>, l: vec3<f32>) -> vec3<f32> {
    let n_l = dot(n, l);
    let n_v = dot(n, v);
    if (n_l <= 0.0 || n_v <= 0.0) {
        return vec3<f32>(0.0);
    }
    let h = normalize(l + v);
    let alpha = max(frame.sheen_roughness * frame.sheen_roughness, 1e-3);
    return frame.sheen_color * (PI * sheen_d(alpha, dot(n, h)) * sheen_visibility(n_l, n_v, alpha));
}

// Linear radiance leaving a mesh point: for each light above the tangent plane,
// (albedo + π f_sheen) · I · colour · max(0, n_s·l)/d² · (1 − K(l in T, B, N)) · V (the macro
// shadow's visibility, 1 without it), plus the fill
// albedo · fill · (½ + ½ n_s.z) that K leaves alone; × coverage. n_s is the shading normal (the
// normal map's), K sees the geometric frame. On the plane z = 0 with T, B, N = X, Y, Z, no
// sheen and no fill this is shade() term for term.
fn shade_mesh(
    world: vec3<f32>,
    normal: vec3<f32>,
    tangent: vec4<f32>,
    p: vec2<f32>,
    uv_scale: f32,
    front: bool,
) -> vec3<f32> {
    let tbn = tangent_frame(front, normal, tangent);
    var lod = 0.0;
//#if PTM_MIP
    lod = mesh_lod(world, tbn[2], uv_scale);
//#endif
    let albedo = albedo_at(p);
//#if PTM
    let c = ptm_coeffs(p, lod);
//#endif
    let ns = normal_at(p, tbn);
    let v = normalize(frame.eye - world);
    var radiance = vec3<f32>(0.0);
    for (var i = 0u; i < frame.light_count; i++) {
        let light = lights[i];
        var to_light = light.position - world;
        var d2 = dot(to_light, to_light);
//#if MESH_DISTANT
        // A distant light: its unit direction, the same everywhere, and no falloff.
        if (light.shape == LIGHT_DISTANT) {
            to_light = light.position;
            d2 = 1.0;
        }
//#endif
        if (d2 <= 0.0) {
            continue;
        }
        let l = to_light / sqrt(d2);
        // The light in the tangent frame: what the PTM's (u, v) map reads.
        let lt = vec3<f32>(dot(l, tbn[0]), dot(l, tbn[1]), dot(l, tbn[2]));
        if (lt.z <= 0.0) {
            continue;
        }
        var visible = vec3<f32>(1.0);
//#if PTM
        // K over the light's footprint as on the plane (a rectangle's sides taken along the
        // tangent frame's axes).
        visible *= 1.0 - ptm_k_area(c, lt, ptm_footprint(lt, lt * sqrt(d2), sqrt(d2), light));
//#endif
//#if SHADOW
        visible *= shadow_visibility(i, world, tbn[2]);
//#endif
        let cos_l = max(dot(ns, l), 0.0);
        radiance += (albedo + sheen_brdf(ns, v, l)) * light.color * (cos_l / d2) * visible;
    }
    radiance += albedo * frame.fill * (0.5 + 0.5 * ns.z);
//#if PTM_COVERAGE
    radiance *= ptm_coverage(p, lod);
//#endif
    return radiance;
}

// `front`: the triangle is counter-clockwise on screen (wgpu's default front face).
@fragment
fn fs_mesh(in: MeshOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    return vec4<f32>(shade_mesh(in.world, in.normal, in.tangent, in.uv, in.uv_scale, front), 1.0);
}
