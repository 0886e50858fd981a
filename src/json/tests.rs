//! The `--json` key snapshot: every object's key paths and JSON types, from a sample of each
//! type with every optional value present and from its `Default` (every optional value
//! missing), against `tests/snapshots/json_keys.txt`; the same list with each key's doc
//! comment is `docs/json.md`. A renamed, added or removed key, or a changed type, fails here.
//! `UPDATE_SNAPSHOTS=1` rewrites both files.
use std::collections::BTreeMap;
use std::path::PathBuf;

use serde_json::Value;

use super::*;

/// A value of a type with every optional part present, so that its JSON shows every key.
trait Sample {
    fn sample() -> Self;
}

fn s<T: Sample>() -> T {
    T::sample()
}

macro_rules! number {
    ($($t:ty = $v:expr),*) => {
        $(impl Sample for $t {
            fn sample() -> Self {
                $v
            }
        })*
    };
}
number!(
    f64 = 0.5,
    f32 = 0.5,
    u32 = 1,
    u64 = 1,
    usize = 1,
    i32 = 1,
    bool = true
);

impl Sample for String {
    fn sample() -> Self {
        "text".into()
    }
}

impl Sample for &'static str {
    fn sample() -> Self {
        "text"
    }
}

impl<T: Sample> Sample for Option<T> {
    fn sample() -> Self {
        Some(s())
    }
}

impl<T: Sample> Sample for Vec<T> {
    fn sample() -> Self {
        vec![s()]
    }
}

impl<T: Sample, const N: usize> Sample for [T; N] {
    fn sample() -> Self {
        std::array::from_fn(|_| s())
    }
}

impl<T: Sample> Sample for Box<T> {
    fn sample() -> Self {
        Box::new(s())
    }
}

impl Sample for Stages {
    fn sample() -> Self {
        Stages(vec![("<stage>", 0.5)])
    }
}

impl Sample for Passes {
    fn sample() -> Self {
        Passes(vec![("<pass>", 0.5)])
    }
}

impl Sample for Failure {
    fn sample() -> Self {
        Failure { error: s() }
    }
}

impl Sample for ErrorInfo {
    fn sample() -> Self {
        ErrorInfo {
            message: s(),
            kind: s(),
            input: s(),
        }
    }
}

impl Sample for Logistic {
    fn sample() -> Self {
        Logistic {
            iterations_mean: s(),
            iterations_max: s(),
            not_converged_texels: s(),
            separable_texels: s(),
            constant_texels: s(),
            lambda: s(),
            ridge_absolute: s(),
            tolerance: s(),
            max_iterations: s(),
            kernel: s(),
        }
    }
}

impl Sample for Auto {
    fn sample() -> Self {
        Auto {
            margin: s(),
            chosen: s(),
            candidates: s(),
        }
    }
}

impl Sample for AutoCandidate {
    fn sample() -> Self {
        AutoCandidate {
            basis: s(),
            holdout_rms_error: s(),
            seconds: s(),
            skipped: s(),
        }
    }
}

impl Sample for Learned {
    fn sample() -> Self {
        Learned {
            terms: s(),
            grid: s(),
            roughness: s(),
            texels: s(),
            alternations: s(),
            kept: s(),
            deviance_start: s(),
            deviance: s(),
            rms_start: s(),
            rms: s(),
            seconds: s(),
        }
    }
}

impl Sample for Eval {
    fn sample() -> Self {
        Eval {
            input: s(),
            output: s(),
            basis: s(),
            width: s(),
            height: s(),
            lights: s(),
        }
    }
}

impl Sample for Stats {
    fn sample() -> Self {
        Stats {
            mean: s(),
            p99: s(),
            max: s(),
        }
    }
}

impl Sample for SkippedPart {
    fn sample() -> Self {
        SkippedPart {
            part: s(),
            skipped: s(),
        }
    }
}

impl Sample for Baked {
    fn sample() -> Self {
        Baked {
            swatch: s(),
            output: s(),
            files: s(),
            shard: s(),
            rows: s(),
            lights_file: s(),
            triangles: s(),
            degenerate_triangles: s(),
            tile: s(),
            seam_mismatch: s(),
            warnings: s(),
            width: s(),
            height: s(),
            texel: s(),
            spp: s(),
            seed: s(),
            lights: s(),
            light_distance: s(),
            device: s(),
            rays: s(),
            mrays_per_s: s(),
            rings: s(),
            copies: s(),
            centred_scenes: s(),
            uncovered_texels: s(),
            below_horizon: s(),
            capped: s(),
            fit: s(),
            maps: s(),
            seconds: s(),
            seconds_load: s(),
            seconds_scene: s(),
            seconds_primary: s(),
            seconds_shadow: s(),
            seconds_fit: s(),
            seconds_write: s(),
        }
    }
}

impl Sample for BakeMaps {
    fn sample() -> Self {
        BakeMaps {
            file: s(),
            png: s(),
            dome_fraction: s(),
        }
    }
}

impl Sample for BakeDevice {
    fn sample() -> Self {
        BakeDevice {
            asked: s(),
            used: s(),
            adapter: s(),
            reason: s(),
        }
    }
}

impl Sample for Rays {
    fn sample() -> Self {
        Rays {
            primary: s(),
            shadow: s(),
            shadow_skipped: s(),
        }
    }
}

impl Sample for BakeFit {
    fn sample() -> Self {
        BakeFit {
            basis: s(),
            link: s(),
            uv: s(),
            mip_levels: s(),
            logistic: s(),
            learned: s(),
            solver: s(),
            rank: s(),
            condition_number: s(),
            rms_error_mean: s(),
            rms_error_p99: s(),
            warnings: s(),
            holdout_lights: s(),
            holdout_rms_error: s(),
            auto: s(),
            stages: s(),
        }
    }
}

impl Sample for Fit {
    fn sample() -> Self {
        Fit {
            input: s(),
            output: s(),
            layout: s(),
            files: s(),
            basis: s(),
            link: s(),
            uv: s(),
            mip_levels: s(),
            logistic: s(),
            learned: s(),
            auto: s(),
            width: s(),
            height: s(),
            texels: s(),
            masked_texels: s(),
            lights: s(),
            lights_fit: s(),
            holdout_lights: s(),
            holdout_default: s(),
            coefficients: s(),
            rank: s(),
            condition_number: s(),
            cutoff: s(),
            rcond: s(),
            singular_values: s(),
            solver: s(),
            weight: s(),
            warnings: s(),
            rms_error: s(),
            max_error: s(),
            holdout_rms_error: s(),
            skipped_samples: s(),
            rank_deficient_texels: s(),
            storage: s(),
            half_error_bound: s(),
            hp_export: s(),
            png_k: s(),
            png_light: s(),
            png_error: s(),
            images: s(),
            seconds: s(),
            seconds_read: s(),
            stages: s(),
            seconds_write: s(),
        }
    }
}

impl Sample for HpExport {
    fn sample() -> Self {
        HpExport {
            path: s(),
            quantisation_error_max: s(),
            quantisation_error_mean: s(),
            scales: s(),
            biases: s(),
        }
    }
}

impl Sample for Images {
    fn sample() -> Self {
        Images {
            decoding: s(),
            srgb_decoded: s(),
            linear: s(),
        }
    }
}

impl Sample for Render {
    fn sample() -> Self {
        Render {
            adapter: s(),
            variant: s(),
            size: s(),
            view: s(),
            tiles: s(),
            lights: s(),
            blur: s(),
            seconds_device: s(),
            caster_downsample: s(),
            nonfinite_coeffs: s(),
            warnings: s(),
            k_unclamped: s(),
            seconds_passes: s(),
            turntable: s(),
            compare_blur: s(),
            png: s(),
            exr: s(),
            mesh: Some(MeshReport {
                maps: s(),
                ..Default::default()
            }),
            seconds: s(),
        }
    }
}

impl Sample for KUnclamped {
    fn sample() -> Self {
        KUnclamped {
            min: s(),
            max: s(),
            clamped_fraction: s(),
            evaluations: s(),
        }
    }
}

impl Sample for Turntable {
    fn sample() -> Self {
        Turntable {
            frames: s(),
            columns: s(),
            rows: s(),
            gutter: s(),
            azimuths_deg: s(),
            seconds_passes: s(),
        }
    }
}

impl Sample for BlurRow {
    fn sample() -> Self {
        BlurRow {
            method: s(),
            max_abs_error: s(),
            mean_abs_error: s(),
            seconds_shade: s(),
            seconds_setup: s(),
        }
    }
}

impl Sample for Window {
    fn sample() -> Self {
        Window {
            adapter: s(),
            surface_format: s(),
            frames: s(),
            renders: s(),
            seconds_last_render: s(),
            blur: s(),
            ptm_on: s(),
            light: s(),
            camera: s(),
            mean_rgb: s(),
        }
    }
}

impl Sample for Swatch {
    fn sample() -> Self {
        Swatch {
            swatch: s(),
            spec: s(),
            output: s(),
            triangles: s(),
            vertices: s(),
            yarns: s(),
            tile: s(),
            bounds: s(),
            volume_per_tile: s(),
            min_yarn_gap: s(),
            seconds: s(),
        }
    }
}

impl Sample for Bounds {
    fn sample() -> Self {
        Bounds { min: s(), max: s() }
    }
}

impl Sample for Report {
    fn sample() -> Self {
        Report {
            report: s(),
            plot: s(),
            contact_sheet: s(),
            csv: s(),
            seconds: s(),
            swatches: s(),
        }
    }
}

impl Sample for ReportSwatch {
    fn sample() -> Self {
        ReportSwatch {
            swatch: s(),
            settings: s(),
            best_rms: s(),
            best: s(),
        }
    }
}

impl Sample for Merge {
    fn sample() -> Self {
        Merge {
            output: s(),
            lights_file: s(),
            kind: s(),
            parts: s(),
            maps: s(),
            width: s(),
            height: s(),
            lights: s(),
            bytes_in: s(),
            bytes_out: s(),
            mb_per_s: s(),
            seconds: s(),
            seconds_merge: s(),
            seconds_write: s(),
        }
    }
}

impl Sample for BatchHere {
    fn sample() -> Self {
        BatchHere {
            outputs: s(),
            seconds: s(),
        }
    }
}

impl Sample for BatchSlurm {
    fn sample() -> Self {
        BatchSlurm {
            bakes: s(),
            tasks: s(),
            dir: s(),
            submit: s(),
        }
    }
}

impl Sample for Convert {
    fn sample() -> Self {
        Convert {
            input: s(),
            from: s(),
            to: s(),
            files: s(),
            width: s(),
            height: s(),
            maps: s(),
        }
    }
}

/// One object `--json` prints: a title, the type whose fields are its keys, and its JSON with
/// every optional value present and with none.
struct Shape {
    title: &'static str,
    root: &'static str,
    full: Value,
    none: Value,
}

fn shape<T: Serialize>(title: &'static str, root: &'static str, full: T, none: T) -> Shape {
    Shape {
        title,
        root,
        full: to_value(&full).unwrap(),
        none: to_value(&none).unwrap(),
    }
}

/// Every object `--json` prints, through the types the commands return.
fn shapes() -> Vec<Shape> {
    vec![
        shape(
            "ptm bake",
            "Baked",
            Bake::Baked(s()),
            Bake::Baked(Default::default()),
        ),
        shape(
            "ptm bake --shard I/N, the part already complete",
            "SkippedPart",
            Bake::Skipped(s()),
            Bake::Skipped(Default::default()),
        ),
        shape("ptm fit", "Fit", Fit::sample(), Fit::default()),
        shape(
            "ptm preview",
            "Render",
            Preview::Render(s()),
            Preview::Render(Default::default()),
        ),
        shape(
            "ptm preview --window",
            "Window",
            Preview::Window(s()),
            Preview::Window(Default::default()),
        ),
        shape("ptm swatch", "Swatch", Swatch::sample(), Swatch::default()),
        shape("ptm report", "Report", Report::sample(), Report::default()),
        shape("ptm merge", "Merge", Merge::sample(), Merge::default()),
        shape(
            "ptm batch",
            "BatchHere",
            Batch::Here(s()),
            Batch::Here(Default::default()),
        ),
        shape(
            "ptm batch --slurm DIR",
            "BatchSlurm",
            Batch::Slurm(s()),
            Batch::Slurm(Default::default()),
        ),
        shape(
            "ptm convert",
            "Convert",
            Convert::sample(),
            Convert::default(),
        ),
        shape("ptm eval", "Eval", Eval::sample(), Eval::default()),
        shape(
            "any failure (every subcommand)",
            "Failure",
            Failure::sample(),
            Failure::default(),
        ),
    ]
}

/// The `Default` of every nested object's type, by type name: where a key's parent is missing
/// from a shape's value-less sample, whether the key can be null or absent is read from its own
/// type's `Default`.
fn nested() -> BTreeMap<&'static str, Value> {
    fn none<T: Serialize + Default>() -> Value {
        to_value(&T::default()).unwrap()
    }
    BTreeMap::from([
        ("ErrorInfo", none::<ErrorInfo>()),
        ("Logistic", none::<Logistic>()),
        ("Learned", none::<Learned>()),
        ("Auto", none::<Auto>()),
        ("AutoCandidate", none::<AutoCandidate>()),
        ("Stats", none::<Stats>()),
        ("Rays", none::<Rays>()),
        ("BakeFit", none::<BakeFit>()),
        ("BakeMaps", none::<BakeMaps>()),
        ("HpExport", none::<HpExport>()),
        ("Images", none::<Images>()),
        ("KUnclamped", none::<KUnclamped>()),
        ("Turntable", none::<Turntable>()),
        ("BlurRow", none::<BlurRow>()),
        ("Bounds", none::<Bounds>()),
        ("ReportSwatch", none::<ReportSwatch>()),
        ("MeshReport", none::<MeshReport>()),
    ])
}

/// A key path (`logistic.iterations_mean`, `compare_blur[].method`) and its JSON type, with
/// `or null` where the key can be null and `or absent` where it can be left out.
#[derive(Debug, PartialEq)]
struct Key {
    path: String,
    kind: String,
    /// The Rust type whose field the key is, and the field (for its doc comment).
    owner: Option<(String, String)>,
}

/// What the value-less sample has where the full one has a value.
#[derive(Clone, Copy)]
enum Missing<'a> {
    /// A value (perhaps null).
    At(&'a Value),
    /// The key is left out of an object that is there.
    Absent,
    /// Its container is missing too (null, absent, an empty array): nothing to learn.
    Unknown,
}

fn json_type(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "bool",
        Value::Number(_) => "number",
        Value::String(_) => "string",
        Value::Array(_) => "array",
        Value::Object(_) => "object",
    }
}

/// `v`'s type in words; `none` says whether it can be null or absent.
fn kind(v: &Value, none: Missing) -> String {
    assert!(
        !v.is_null(),
        "a sample value is null: give the sample a value"
    );
    let base = match v {
        Value::Array(a) => {
            let first = a.first().expect("a sample array has one element");
            let inner = match none {
                Missing::At(Value::Array(d)) => d.first().map_or(Missing::Unknown, Missing::At),
                _ => Missing::Unknown,
            };
            let element = kind(first, inner);
            if element.contains(' ') {
                format!("array of ({element})")
            } else {
                format!("array of {element}")
            }
        }
        _ => json_type(v).to_string(),
    };
    match none {
        Missing::At(Value::Null) => format!("{base} or null"),
        Missing::Absent => format!("{base} or absent"),
        _ => base,
    }
}

/// The fields of every struct in src/json.rs: (struct, field) → (type text, doc, flattened),
/// and the doc of every tuple struct (a map written by hand).
struct Source {
    fields: BTreeMap<(String, String), (String, String, bool)>,
    maps: BTreeMap<String, String>,
    /// [`nested`].
    nested: BTreeMap<&'static str, Value>,
}

fn source() -> Source {
    let text = include_str!("../json.rs");
    let mut fields = BTreeMap::new();
    let mut maps = BTreeMap::new();
    let mut owner: Option<String> = None;
    let mut doc = String::new();
    let mut flatten = false;
    for line in text.lines() {
        let t = line.trim();
        if let Some(d) = t.strip_prefix("///") {
            if !doc.is_empty() {
                doc.push(' ');
            }
            doc.push_str(d.trim());
            continue;
        }
        if t == "#[serde(flatten)]" {
            flatten = true;
            continue;
        }
        if t.starts_with("#[") {
            continue;
        }
        if let Some(rest) = t.strip_prefix("pub struct ") {
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if rest[name.len()..].starts_with('(') {
                maps.insert(name, std::mem::take(&mut doc));
            } else {
                owner = Some(name);
            }
        } else if t == "}" {
            owner = None;
        } else if let (Some(o), Some(rest)) = (&owner, t.strip_prefix("pub ")) {
            if let Some((field, ty)) = rest.split_once(": ") {
                let ty = ty.trim_end_matches(',').to_string();
                fields.insert((o.clone(), field.to_string()), (ty, doc.clone(), flatten));
            }
        }
        doc.clear();
        flatten = false;
    }
    Source {
        fields,
        maps,
        nested: nested(),
    }
}

impl Source {
    /// The struct (or map type) named in a field's type text, e.g. `Logistic` in
    /// `Option<Logistic>`.
    fn child(&self, ty: &str) -> Option<String> {
        ty.split(|c: char| !(c.is_alphanumeric() || c == '_'))
            .find(|w| self.maps.contains_key(*w) || self.fields.keys().any(|(s, _)| s == w))
            .map(str::to_string)
    }

    /// The (struct, field) that key `k` of an object of type `owner` comes from: the field of
    /// that name, or the flattened map that writes it.
    fn field(&self, owner: &str, k: &str) -> Option<(String, String)> {
        let key = (owner.to_string(), k.to_string());
        if self.fields.contains_key(&key) {
            return Some(key);
        }
        self.fields
            .iter()
            .find(|((s, _), (_, _, flat))| s == owner && *flat)
            .map(|(k, _)| k.clone())
    }
}

/// Every key path under `v` (an object of type `owner`), its type and where it comes from.
fn walk(
    v: &Value,
    none: Missing,
    owner: Option<&str>,
    prefix: &str,
    src: &Source,
    out: &mut Vec<Key>,
) {
    // Below a parent the value-less sample leaves out, the type's own `Default` says.
    let none = match (none, owner, v) {
        (Missing::At(Value::Object(_)), _, _) | (_, _, Value::Array(_)) | (_, None, _) => none,
        (_, Some(o), Value::Object(_)) if !src.maps.contains_key(o) => {
            let d = src
                .nested
                .get(o)
                .unwrap_or_else(|| panic!("register the nested --json type {o} in `nested()`"));
            Missing::At(d)
        }
        _ => none,
    };
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let path = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                let inner = match none {
                    Missing::At(Value::Object(d)) => d.get(k).map_or(Missing::Absent, Missing::At),
                    _ => Missing::Unknown,
                };
                let field = owner.and_then(|o| src.field(o, k));
                let child = field
                    .as_ref()
                    .and_then(|f| src.child(&src.fields[f].0))
                    .filter(|c| Some(c.as_str()) != owner);
                out.push(Key {
                    path: path.clone(),
                    kind: kind(x, inner),
                    owner: field.or_else(|| owner.map(|o| (o.to_string(), String::new()))),
                });
                walk(x, inner, child.as_deref(), &path, src, out);
            }
        }
        Value::Array(a) => {
            let inner = match none {
                Missing::At(Value::Array(d)) => d.first().map_or(Missing::Unknown, Missing::At),
                _ => Missing::Unknown,
            };
            if let Some(first) = a.first() {
                walk(first, inner, owner, &format!("{prefix}[]"), src, out);
            }
        }
        _ => {}
    }
}

fn keys(shape: &Shape, src: &Source) -> Vec<Key> {
    let mut out = Vec::new();
    walk(
        &shape.full,
        Missing::At(&shape.none),
        Some(shape.root),
        "",
        src,
        &mut out,
    );
    out
}

/// The snapshot: per object, one line per key path.
fn snapshot(shapes: &[Shape], src: &Source) -> String {
    let mut text = String::from(
        "# The key paths of every object `ptm --json` prints, with their JSON types; generated from\n\
         # src/json.rs by its unit tests (`UPDATE_SNAPSHOTS=1 cargo test -p ptm --bin ptm json::`\n\
         # rewrites this file and docs/json.md). A change here is a change for every pipeline that\n\
         # reads the JSON.\n",
    );
    for shape in shapes {
        text += &format!("\n[{}]\n", shape.title);
        for k in keys(shape, src) {
            text += &format!("{}: {}\n", k.path, k.kind);
        }
    }
    text
}

/// What a key means: its field's doc comment, or for the keys of a map type (`<pass>`) the
/// map type's.
fn meaning(k: &Key, src: &Source) -> String {
    let Some((owner, field)) = &k.owner else {
        return String::new();
    };
    match src.fields.get(&(owner.clone(), field.clone())) {
        Some((_, doc, _)) => doc.clone(),
        None => src.maps.get(owner).cloned().unwrap_or_default(),
    }
}

/// docs/json.md: the snapshot as tables, with each key's meaning.
fn markdown(shapes: &[Shape], src: &Source) -> String {
    let mut md = String::from(
        "# The `--json` objects\n\n\
         Every subcommand takes `--json` and then prints exactly one JSON object on stdout (keys in\n\
         alphabetical order); progress and messages go to stderr. On any failure, argument errors\n\
         included, the object is `{\"error\": {…}}` (last table) and the exit code is the usual one\n\
         (2 for usage, 1 otherwise). Timings are `seconds` (the whole run) and `seconds_<stage>`.\n\n\
         A type \"or null\" means the key is always there and null where it does not apply; \"or\n\
         absent\" means the key is left out where it does not apply. A key path `a.b` is key `b`\n\
         of the object at `a`; `a[].b` is key `b` of every element of the array `a`; `<stage>`\n\
         and `<pass>` stand for the names the libraries give their stages and render passes.\n\n\
         This file is generated from the types in `src/json.rs` (each key is a field there) by\n\
         `cargo test -p ptm`, which fails when it or `tests/snapshots/json_keys.txt` differs from\n\
         the types; `UPDATE_SNAPSHOTS=1 cargo test -p ptm --bin ptm json::` rewrites both.\n",
    );
    for shape in shapes {
        md += &format!(
            "\n## `{}`\n\n| key | type | meaning |\n|---|---|---|\n",
            shape.title
        );
        for k in keys(shape, src) {
            md += &format!(
                "| `{}` | {} | {} |\n",
                k.path,
                k.kind,
                meaning(&k, src).replace('|', "\\|")
            );
        }
    }
    md
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `want` is the content of `path`, or with `UPDATE_SNAPSHOTS=1` becomes it.
fn check_file(path: &str, want: &str) {
    let file = root().join(path);
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        std::fs::write(&file, want).unwrap();
        eprintln!("wrote {}", file.display());
        return;
    }
    let have = std::fs::read_to_string(&file).unwrap_or_default();
    if have != want {
        let first = have
            .lines()
            .zip(want.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(have.lines().count().min(want.lines().count()));
        panic!(
            "{path} differs from the --json types at line {} (have {:?}, the types give {:?}): \
             a key was renamed, added, removed or changed type. If that is meant, rerun with \
             UPDATE_SNAPSHOTS=1 and say so to the pipelines that read the JSON",
            first + 1,
            have.lines().nth(first),
            want.lines().nth(first)
        );
    }
}

#[test]
fn json_keys_match_the_snapshot_and_docs() {
    let src = source();
    let shapes = shapes();
    check_file("tests/snapshots/json_keys.txt", &snapshot(&shapes, &src));
    check_file("docs/json.md", &markdown(&shapes, &src));
}

#[test]
fn every_key_has_a_meaning() {
    let src = source();
    for shape in shapes() {
        for k in keys(&shape, &src) {
            assert!(
                !meaning(&k, &src).is_empty(),
                "{}: key {} has no doc comment in src/json.rs",
                shape.title,
                k.path
            );
        }
    }
}

/// The keys the README and the other docs name in words (`seconds_write`, the `error` object's
/// keys) are keys of the objects.
#[test]
fn the_keys_the_docs_name_exist() {
    let src = source();
    let shapes = shapes();
    let all: Vec<String> = shapes
        .iter()
        .flat_map(|s| keys(s, &src))
        .map(|k| {
            k.path
                .rsplit('.')
                .next()
                .unwrap()
                .trim_end_matches("[]")
                .to_string()
        })
        .collect();
    let mut docs = vec![root().join("README.md")];
    for e in std::fs::read_dir(root().join("docs")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") && !p.ends_with("json.md") {
            docs.push(p);
        }
    }
    let mut named = 0;
    for doc in &docs {
        let text = std::fs::read_to_string(doc).unwrap();
        for (i, span) in text.split('`').enumerate() {
            // Odd pieces are inside backticks.
            if i % 2 == 0 {
                continue;
            }
            let timing = span == "seconds" || span.starts_with("seconds_");
            if timing
                && span
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || "_<>".contains(c))
            {
                assert!(
                    all.iter().any(|k| k == span),
                    "{} names the --json key `{span}`, which no object has",
                    doc.display()
                );
                named += 1;
            }
            if let Some(rest) = span.strip_prefix("{\"error\": {") {
                let want: Vec<&str> = rest
                    .trim_end_matches("}}")
                    .split(',')
                    .map(|w| w.trim().trim_matches('"'))
                    .collect();
                let error = shapes.iter().find(|s| s.root == "Failure").unwrap();
                let have: Vec<String> = error.full["error"]
                    .as_object()
                    .unwrap()
                    .keys()
                    .cloned()
                    .collect();
                let mut want_sorted: Vec<String> = want.iter().map(|w| w.to_string()).collect();
                want_sorted.sort();
                assert_eq!(
                    want_sorted,
                    have,
                    "{}: the error object's keys",
                    doc.display()
                );
                named += 1;
            }
        }
    }
    assert!(
        named > 0,
        "the README names no --json key: has its paragraph moved?"
    );
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    assert!(
        readme.contains("docs/json.md"),
        "README.md should link docs/json.md, the list of --json keys"
    );
}

/// A fit's stages become `seconds_<stage>` keys of the object they are flattened into.
#[test]
fn stages_are_flattened_into_seconds_keys() {
    let fit = BakeFit {
        stages: Stages(vec![("mip levels", 1.0), ("newton", 2.0)]),
        ..Default::default()
    };
    let v = to_value(&fit).unwrap();
    assert_eq!(v["seconds_mip_levels"], 1.0);
    assert_eq!(v["seconds_newton"], 2.0);
    assert!(v.get("stages").is_none(), "{v}");
}
