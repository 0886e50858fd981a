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
// (albedo + π f_sheen) · I · colour · max(0, n_s·l)/d² · (1 − K(l in T, B, N)), plus the fill
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
        let to_light = light.position - world;
        let d2 = dot(to_light, to_light);
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
