//! The WGSL of the GPU bake validated with naga (shader breakage shows without a GPU), and its
//! structs' layouts against the Rust twins', field by field.
use ptm_gpubake::baker::{Hit, PrimaryParams, Sample, ShadowParams, SHADER};

fn module() -> (naga::Module, naga::valid::ModuleInfo) {
    let module = naga::front::wgsl::parse_str(SHADER).expect("trace.wgsl parses");
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::RAY_QUERY,
    )
    .validate(&module)
    .expect("trace.wgsl validates");
    (module, info)
}

/// (member name, offset) of the WGSL struct `name`, and its size.
fn layout(m: &naga::Module, name: &str) -> (Vec<(String, u32)>, u32) {
    for (_, ty) in m.types.iter() {
        if ty.name.as_deref() == Some(name) {
            if let naga::TypeInner::Struct { members, span } = &ty.inner {
                let fields = members
                    .iter()
                    .map(|f| (f.name.clone().unwrap_or_default(), f.offset))
                    .collect();
                return (fields, *span);
            }
        }
    }
    panic!("no struct {name} in trace.wgsl")
}

#[test]
fn shader_validates_and_structs_match_their_rust_twins() {
    let (m, _) = module();
    let entries: Vec<&str> = m.entry_points.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(entries, ["primary", "shadow"]);
    let check = |name: &str, rust: &[(&str, usize)], size: usize| {
        let (wgsl, span) = layout(&m, name);
        let want: Vec<(String, u32)> = rust
            .iter()
            .map(|(n, o)| (n.to_string(), *o as u32))
            .collect();
        assert_eq!(wgsl, want, "{name}");
        assert_eq!(span as usize, size, "{name} size");
    };
    use std::mem::{offset_of, size_of};
    check(
        "PrimaryParams",
        &[
            ("z_top", offset_of!(PrimaryParams, z_top)),
            ("t_max", offset_of!(PrimaryParams, t_max)),
            ("count", offset_of!(PrimaryParams, count)),
            ("_pad", offset_of!(PrimaryParams, _pad)),
        ],
        size_of::<PrimaryParams>(),
    );
    check(
        "Hit",
        &[("t", offset_of!(Hit, t)), ("prim", offset_of!(Hit, prim))],
        size_of::<Hit>(),
    );
    check(
        "ShadowParams",
        &[
            ("dir", offset_of!(ShadowParams, dir)),
            ("z_cap", offset_of!(ShadowParams, z_cap)),
            ("pos", offset_of!(ShadowParams, pos)),
            ("point", offset_of!(ShadowParams, point)),
            ("texels", offset_of!(ShadowParams, texels)),
            ("spp", offset_of!(ShadowParams, spp)),
            ("out_offset", offset_of!(ShadowParams, out_offset)),
            ("slot", offset_of!(ShadowParams, slot)),
        ],
        size_of::<ShadowParams>(),
    );
    check(
        "Sample",
        &[
            ("org", offset_of!(Sample, org)),
            ("covered", offset_of!(Sample, covered)),
            ("n", offset_of!(Sample, n)),
            ("_pad", offset_of!(Sample, _pad)),
        ],
        size_of::<Sample>(),
    );
}
