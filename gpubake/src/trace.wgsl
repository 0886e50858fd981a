// The GPU bake's two passes over a band of texel rows (gpubake/src/baker.rs owns the pipelines):
// `primary`, one downward ray per footprint sample from the camera plane (the closest hit's
// distance and triangle, read back: the CPU turns them into shadow origins exactly as the
// Embree bake does), and `shadow`, per texel of the band and one light, one shadow ray per
// covered footprint sample, the occluded ones counted. The CPU twin of both is ptm-bake's
// Embree baker (bake/src/visibility.rs); gpubake/tests/agreement.rs compares them.
enable wgpu_ray_query;

// A triangle index meaning "the primary ray hit nothing".
const NO_HIT: u32 = 0xffffffffu;
// Invocations per workgroup; dispatches are 2-D (at most 65,535 workgroups per dimension), so
// the flat index is x + y · (workgroups in x) · WORKGROUP.
const WORKGROUP: u32 = 64u;

// Group 0, binding 0 for both passes: the TLAS of the tile copies the pass needs.
@group(0) @binding(0) var acc: acceleration_structure;

// ---- primary ----------------------------------------------------------------------------------

// `PrimaryParams` in baker.rs, field for field.
struct PrimaryParams {
    // Height of the camera plane: the clamp plane z_cap, in f32 (baker units).
    z_top: f32,
    // Far end of a primary ray (beyond the lowest geometry).
    t_max: f32,
    // Footprint samples in the band.
    count: u32,
    _pad: u32,
}

// `Hit` in baker.rs: the closest hit's distance and triangle (NO_HIT: none).
struct Hit {
    t: f32,
    prim: u32,
}

@group(0) @binding(1) var<uniform> primary_params: PrimaryParams;
// Sample positions (x, y) on the camera plane, texel-major then sample, as ptm_bake::sample_xy.
@group(0) @binding(2) var<storage, read> sample_xy: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> hits: array<Hit>;

@compute @workgroup_size(64)
fn primary(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = id.x + id.y * groups.x * WORKGROUP;
    if i >= primary_params.count {
        return;
    }
    let org = vec3<f32>(sample_xy[i], primary_params.z_top);
    var rq: ray_query;
    rayQueryInitialize(&rq, acc, RayDesc(RAY_FLAG_NONE, 0xFFu, 0.0, primary_params.t_max, org, vec3<f32>(0.0, 0.0, -1.0)));
    while rayQueryProceed(&rq) {}
    let h = rayQueryGetCommittedIntersection(&rq);
    if h.kind == RAY_QUERY_INTERSECTION_NONE {
        hits[i] = Hit(0.0, NO_HIT);
    } else {
        hits[i] = Hit(h.t, h.primitive_index);
    }
}

// ---- shadow -----------------------------------------------------------------------------------

// `ShadowParams` in baker.rs: one light of a pass (a uniform at a per-light offset).
struct ShadowParams {
    // A distant light: the unit direction towards it (l_z > 0), in f32 as the CPU bake traces it.
    dir: vec3<f32>,
    // The clamp plane: shadow rays end where they reach it.
    z_cap: f32,
    // A point light: its position (baker units).
    pos: vec3<f32>,
    // 1: a point light at `pos` (rays end at the light, each texel's mean direction to it is
    // written to `uv`); 0: a distant light along `dir`.
    point: u32,
    // Texels in the band.
    texels: u32,
    // Footprint samples per texel.
    spp: u32,
    // Where this light's counts (and (u, v)) start: its slot in the pass × texels.
    out_offset: u32,
    // This light's slot in the pass (its entry of `traced`).
    slot: u32,
}

// `Sample` in baker.rs: one footprint sample's shadow-ray origin and face-forwarded unit normal.
struct Sample {
    org: vec3<f32>,
    // 1 where the primary ray hit the swatch, 0 where it saw nothing.
    covered: u32,
    n: vec3<f32>,
    _pad: u32,
}

@group(0) @binding(4) var<uniform> light: ShadowParams;
@group(0) @binding(5) var<storage, read> samples: array<Sample>;
// Per light slot and texel: occluded samples.
@group(0) @binding(6) var<storage, read_write> occluded: array<u32>;
// Per light slot: shadow rays traced (covered samples facing the light).
@group(0) @binding(7) var<storage, read_write> traced: array<atomic<u32>>;
// Per light slot and texel, point lights only: (u, v) of the mean unit direction to the light
// over the texel's covered samples (0 where none is covered).
@group(0) @binding(8) var<storage, read_write> uv: array<vec2<f32>>;

// The far end of a ray that never reaches the clamp plane (f32's largest value).
const FAR: f32 = 3.40282347e38;

// Shadow rays a workgroup traced, summed here first: one atomic per workgroup on the light's
// counter instead of one per texel (64 invocations contending for one address).
var<workgroup> group_rays: atomic<u32>;

@compute @workgroup_size(64)
fn shadow(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lane: u32,
) {
    let texel = id.x + id.y * groups.x * WORKGROUP;
    var rays = 0u;
    if texel < light.texels {
        rays = shadow_texel(texel);
    }
    atomicAdd(&group_rays, rays);
    workgroupBarrier();
    if lane == 0u {
        atomicAdd(&traced[light.slot], atomicLoad(&group_rays));
    }
}

// One texel of the band under one light: its samples' shadow rays in order, the occluded ones
// counted into `occluded` (and a point light's mean direction into `uv`). Returns the rays
// traced.
fn shadow_texel(texel: u32) -> u32 {
    let point = light.point != 0u;
    var count = 0u;
    var rays = 0u;
    var covered = 0u;
    var dir_sum = vec3<f32>(0.0);
    // Declared once, outside the loop: Mesa 25's lavapipe loses the device compiling a ray
    // query declared in a loop body (wgpu 30, naga's SPIR-V), and one query reinitialised per
    // ray is what a ray-tracing API expects anyway.
    var rq: ray_query;
    for (var s = 0u; s < light.spp; s++) {
        // Sample-major within the band: neighbouring invocations (texels) read neighbouring
        // samples.
        let smp = samples[s * light.texels + texel];
        if smp.covered == 0u {
            continue;
        }
        covered += 1u;
        // As the CPU bake: towards a distant light, or to a point light (not normalised: the
        // ray ends at t = 1, the light), whose unit direction every covered sample sums.
        var d = light.dir;
        if point {
            d = light.pos - smp.org;
            dir_sum += d / length(d);
        }
        // A sample facing away from the light is occluded without a ray.
        let facing = d.x * smp.n.x + d.y * smp.n.y + d.z * smp.n.z > 0.0;
        if !facing {
            count += 1u;
            continue;
        }
        rays += 1u;
        // From the origin to the clamp plane, where nothing lies above, and no further than a
        // point light.
        var t_far = FAR;
        if d.z > 0.0 {
            t_far = max((light.z_cap - smp.org.z) / d.z, 0.0);
        }
        if point {
            t_far = min(t_far, 1.0);
        }
        rayQueryInitialize(&rq, acc, RayDesc(RAY_FLAG_TERMINATE_ON_FIRST_HIT, 0xFFu, 0.0, t_far, smp.org, d));
        while rayQueryProceed(&rq) {}
        if rayQueryGetCommittedIntersection(&rq).kind != RAY_QUERY_INTERSECTION_NONE {
            count += 1u;
        }
    }
    if point {
        var mean = vec2<f32>(0.0);
        let len = length(dir_sum);
        if covered > 0u && len > 0.0 {
            mean = dir_sum.xy / len;
        }
        uv[light.out_offset + texel] = mean;
    }
    occluded[light.out_offset + texel] = count;
    return rays;
}
