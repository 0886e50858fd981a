//! The stored sample stack: what `ptm bake` writes (`samples.exr`) and `ptm fit` reads.
//!
//! Layout (docs/FORMAT.md): one single-part, ZIP-compressed, float32 EXR of width × height
//! texels; row 0 is the far edge y = H. Channels: `K.0000`, `K.0001`, … (K for light i, in light
//! order), `coverage`, and for finite-distance lights `u.0000`/`v.0000`, … (the per-texel
//! projection of the direction towards light i). Header: `stack:version`, `stack:tileW`,
//! `stack:tileH` (f64), `stack:nLights` (i32), `stack:lightDirs` (text vector, "x y z" per light,
//! shortest round-trip decimal), `stack:lightNames` (text vector), `stack:K`, `stack:frame`.
use std::path::Path;

use crate::{Error, Result};
use ptm_format::exrio::{self, Attr, Samples};
use ptm_format::LightSet;

/// Value of `stack:version`; a file without it is not a sample stack.
pub const STACK_VERSION: &str = "ptm-samples/1";

/// The stored sample stack a bake writes (`samples.exr`) and `ptm fit` reads.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleStack {
    /// Texels per row.
    pub width: usize,
    /// Rows; row 0 is the far edge y = H of the tile.
    pub height: usize,
    /// Tile size (W, H) in swatch units.
    pub tile: [f64; 2],
    /// Light order = channel order `K.0000`, `K.0001`, ….
    pub lights: LightSet,
    /// `k[light][texel]`: occluded fraction (0 = lit, 1 = occluded), row-major.
    pub k: Vec<Vec<f32>>,
    /// Per texel, the fraction of footprint samples that hit the swatch (0 = masked).
    pub coverage: Vec<f32>,
    /// Finite-distance lights only: per light, per texel, the (u, v) of the unit vector from
    /// the texel towards the light (the distant direction `lights.dirs` is then nominal).
    pub uv: Option<Vec<Vec<[f32; 2]>>>,
}

/// Name of the K channel of light `i`.
pub fn k_channel(i: usize) -> String {
    format!("K.{i:04}")
}

/// Named EXR channels, as `exrio` takes them.
type Channels = Vec<(String, Samples)>;

impl SampleStack {
    /// A stack of distant `lights` over a `width × height` image of a `tile`, every texel fully
    /// covered: what a pipeline that renders its own K (another renderer, a capture) fits.
    /// `k[light][texel]` as the field; set `coverage` for holes.
    pub fn new(
        lights: LightSet,
        width: usize,
        height: usize,
        tile: [f64; 2],
        k: Vec<Vec<f32>>,
    ) -> SampleStack {
        SampleStack {
            width,
            height,
            tile,
            lights,
            k,
            coverage: vec![1.0; width * height],
            uv: None,
        }
    }

    /// Bytes the K planes of a `width × height` stack of `lights` lights take while it is
    /// written: an f32 per texel and light, and with per-texel directions (`per_texel_uv`,
    /// finite-distance lights) also its (u, v) pair and the encoder's split of those into u and
    /// v channels (8 + 8 more). The coverage plane is the baker's. In f64, so that absurd
    /// requests are measured rather than overflow.
    pub fn memory_bytes(width: usize, height: usize, lights: usize, per_texel_uv: bool) -> f64 {
        let per = if per_texel_uv { 20.0 } else { 4.0 };
        width as f64 * height as f64 * lights as f64 * per
    }

    /// Texel count.
    pub fn texels(&self) -> usize {
        self.width * self.height
    }

    /// Checks that every plane has width × height entries and one plane per light.
    pub fn validate(&self) -> Result<()> {
        let n = self.texels();
        let bad = |r: String| Err(Error::Invalid(format!("sample stack: {r}")));
        if n == 0 {
            return bad(format!("empty image {}×{}", self.width, self.height));
        }
        if self.lights.is_empty() {
            return bad("no lights".into());
        }
        if self.k.len() != self.lights.len() {
            return bad(format!(
                "{} K planes for {} lights",
                self.k.len(),
                self.lights.len()
            ));
        }
        if let Some(i) = self.k.iter().position(|p| p.len() != n) {
            return bad(format!(
                "K plane {i} has {} texels, expected {n}",
                self.k[i].len()
            ));
        }
        if self.coverage.len() != n {
            return bad(format!(
                "coverage has {} texels, expected {n}",
                self.coverage.len()
            ));
        }
        if let Some(uv) = &self.uv {
            if uv.len() != self.lights.len() || uv.iter().any(|p| p.len() != n) {
                return bad("uv planes do not match the lights and texels".into());
            }
        }
        if !(self.tile[0] > 0.0 && self.tile[1] > 0.0) {
            return bad(format!("tile size {:?} is not positive", self.tile));
        }
        Ok(())
    }

    /// Writes the stack as EXR, atomically (temporary file, then rename).
    pub fn write(&self, path: &Path) -> Result<()> {
        self.clone().write_into(path)
    }

    /// As [`SampleStack::write`], handing the K planes to the EXR writer instead of copying
    /// them: the peak memory of a large stack stays one stack.
    pub fn write_into(self, path: &Path) -> Result<()> {
        let bytes = self.encode_into(path)?;
        Ok(ptm_format::atomic::write_bytes(path, &bytes)?)
    }

    /// The bytes [`SampleStack::write_into`] writes (`path` names the file in errors only), to
    /// stage in an [`atomic::Transaction`](ptm_format::atomic::Transaction) with other outputs.
    pub fn encode_into(mut self, path: &Path) -> Result<Vec<u8>> {
        self.validate()?;
        let k = std::mem::take(&mut self.k);
        let (channels, attrs) = self.channels(k);
        Ok(exrio::encode(
            path,
            self.width,
            self.height,
            channels,
            attrs,
        )?)
    }

    /// The EXR channels (K planes taken, not copied) and header attributes of the stack.
    fn channels(&self, k: Vec<Vec<f32>>) -> (Channels, Vec<(&'static str, Attr)>) {
        let mut channels = Vec::with_capacity(k.len() * 3 + 1);
        for (i, plane) in k.into_iter().enumerate() {
            channels.push((k_channel(i), Samples::F32(plane)));
        }
        channels.push(("coverage".to_string(), Samples::F32(self.coverage.clone())));
        if let Some(uv) = &self.uv {
            for (i, plane) in uv.iter().enumerate() {
                let u = plane.iter().map(|p| p[0]).collect();
                let v = plane.iter().map(|p| p[1]).collect();
                channels.push((format!("u.{i:04}"), Samples::F32(u)));
                channels.push((format!("v.{i:04}"), Samples::F32(v)));
            }
        }
        (channels, self.header_attrs())
    }

    /// The `stack:*` header attributes of this stack (also written into farm parts, whose
    /// merge copies them into the whole stack's header).
    pub(crate) fn header_attrs(&self) -> Vec<(&'static str, Attr)> {
        let dirs = self
            .lights
            .dirs
            .iter()
            .map(|d| format!("{:e} {:e} {:e}", d[0], d[1], d[2]))
            .collect();
        vec![
            ("stack:version", Attr::Text(STACK_VERSION.into())),
            ("stack:tileW", Attr::F64(self.tile[0])),
            ("stack:tileH", Attr::F64(self.tile[1])),
            ("stack:nLights", Attr::I32(self.lights.len() as i32)),
            ("stack:lightDirs", Attr::Texts(dirs)),
            ("stack:lightNames", Attr::Texts(self.lights.names.clone())),
            (
                "stack:K",
                Attr::Text(
                    "K = occluded fraction of the texel footprint: 0 lit, 1 occluded".into(),
                ),
            ),
            (
                "stack:frame",
                Attr::Text(
                    "tile [0,W]x[0,H], z up, u = l.X, v = l.Y, row 0 at y = H, column 0 at x = 0"
                        .into(),
                ),
            ),
            (
                "stack:uv",
                Attr::Text(
                    if self.uv.is_some() {
                        "per-texel"
                    } else {
                        "distant"
                    }
                    .into(),
                ),
            ),
        ]
    }

    /// Reads a stack written by [`SampleStack::write`]. A file that is not a sample stack, or
    /// lacks a channel or attribute, is an error saying which.
    pub fn read(path: &Path) -> Result<Self> {
        let mut c = exrio::read(path)?;
        const WHAT: &str = "sample stack";
        match c.attrs.get("stack:version") {
            Some(Attr::Text(v)) if v == STACK_VERSION => {}
            Some(Attr::Text(v)) => {
                return Err(c.error(format!(
                    "sample stack version {v:?} is not supported (expected {STACK_VERSION:?})"
                )))
            }
            _ => {
                let hint = if c.attrs.contains_key("ptm:basis") {
                    " (it is a fitted PTM: pass the samples.exr written by `ptm bake`)"
                } else if c.attrs.contains_key("maps:version") {
                    " (it holds the companion maps `ptm bake --maps` writes: pass the \
                     samples.exr beside it)"
                } else {
                    " (no `stack:version` attribute: pass the samples.exr written by `ptm bake`)"
                };
                return Err(c.error(format!("not a ptm sample stack{hint}")));
            }
        }
        let tile = [c.f64("stack:tileW", WHAT)?, c.f64("stack:tileH", WHAT)?];
        let dir_text = c.texts("stack:lightDirs", WHAT)?;
        let mut dirs = Vec::with_capacity(dir_text.len());
        for (i, s) in dir_text.iter().enumerate() {
            let v: Vec<f64> = s
                .split_whitespace()
                .filter_map(|t| t.parse().ok())
                .collect();
            if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
                return Err(c.error(format!("light {i} direction {s:?} is not `x y z`")));
            }
            dirs.push([v[0], v[1], v[2]]);
        }
        let names = c.texts("stack:lightNames", WHAT)?;
        if names.len() != dirs.len() {
            return Err(c.error(format!(
                "{} light names for {} light directions",
                names.len(),
                dirs.len()
            )));
        }
        let n = c.f64("stack:nLights", WHAT)? as usize;
        if n != dirs.len() {
            return Err(c.error(format!(
                "header says {n} lights but lists {} directions",
                dirs.len()
            )));
        }
        // Directions were written normalised; keep them bit-exact rather than renormalising.
        let lights = LightSet { names, dirs };
        let per_texel = matches!(c.attrs.get("stack:uv"), Some(Attr::Text(s)) if s == "per-texel");
        let (k, coverage, uv) = take_planes(&mut c, n, per_texel, WHAT)?;
        let stack = SampleStack {
            width: c.width,
            height: c.height,
            tile,
            lights,
            k,
            coverage,
            uv,
        };
        stack
            .validate()
            .map_err(|e| c.error::<Error>(e.to_string()))?;
        Ok(stack)
    }
}

/// The sample planes of `n` lights from a stack-like file (a stack or a farm part of one):
/// `K.0000`…, `coverage`, and for per-texel directions `u.0000`/`v.0000`….
pub(crate) type Planes = (Vec<Vec<f32>>, Vec<f32>, Option<Vec<Vec<[f32; 2]>>>);

pub(crate) fn take_planes(
    c: &mut exrio::Contents,
    n: usize,
    per_texel: bool,
    what: &str,
) -> Result<Planes> {
    let mut k = Vec::with_capacity(n);
    for i in 0..n {
        k.push(c.take_f32(&k_channel(i), what)?);
    }
    let coverage = c.take_f32("coverage", what)?;
    let uv = if per_texel {
        let mut uv = Vec::with_capacity(n);
        for i in 0..n {
            let u = c.take_f32(&format!("u.{i:04}"), what)?;
            let v = c.take_f32(&format!("v.{i:04}"), what)?;
            uv.push(u.into_iter().zip(v).map(|(u, v)| [u, v]).collect());
        }
        Some(uv)
    } else {
        None
    };
    Ok((k, coverage, uv))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small_stack(uv: bool) -> SampleStack {
        let lights = LightSet::from_dirs([[0.3, -0.2, 0.9], [0.0, 0.0, 1.0], [-1.0, 0.1, 0.05]]);
        let (w, h) = (5, 3);
        let k: Vec<Vec<f32>> = (0..3)
            .map(|l| (0..w * h).map(|t| (t * 7 + l * 3) as f32 / 37.0).collect())
            .collect();
        let uv = uv.then(|| {
            (0..3)
                .map(|l| {
                    (0..w * h)
                        .map(|t| [t as f32 * 0.01 - 0.1, l as f32 * 0.2 - 0.3])
                        .collect()
                })
                .collect()
        });
        SampleStack {
            width: w,
            height: h,
            tile: [1.25, 0.5],
            lights,
            k,
            coverage: (0..w * h).map(|t| (t % 4) as f32 / 3.0).collect(),
            uv,
        }
    }

    #[test]
    fn round_trip_is_exact() {
        let dir = std::env::temp_dir().join(format!("ptm-fit-stack-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for uv in [false, true] {
            let s = small_stack(uv);
            let p = dir.join(format!("s{uv}.exr"));
            s.write(&p).unwrap();
            let back = SampleStack::read(&p).unwrap();
            assert_eq!(s, back);
            // The same content gives the same bytes (header attributes in a fixed order),
            // whatever order the exr crate's attribute map iterates in.
            let again = dir.join(format!("again{uv}.exr"));
            for _ in 0..4 {
                s.write(&again).unwrap();
                assert!(std::fs::read(&p).unwrap() == std::fs::read(&again).unwrap());
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn foreign_truncated_and_incomplete_files_are_named_errors() {
        let dir = std::env::temp_dir().join(format!("ptm-fit-stack-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // Not an EXR at all.
        let p = dir.join("text.exr");
        std::fs::write(&p, "hello").unwrap();
        let e = SampleStack::read(&p).unwrap_err().to_string();
        assert!(e.contains("text.exr") && e.contains("OpenEXR"), "{e}");
        // A valid EXR that is not a stack.
        let p = dir.join("foreign.exr");
        exrio::write(
            &p,
            2,
            2,
            vec![("R".into(), Samples::F32(vec![0.0; 4]))],
            vec![],
        )
        .unwrap();
        let e = SampleStack::read(&p).unwrap_err().to_string();
        assert!(e.contains("not a ptm sample stack"), "{e}");
        // Truncated stack.
        let s = small_stack(false);
        let p = dir.join("trunc.exr");
        s.write(&p).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 40]).unwrap();
        let e = SampleStack::read(&p).unwrap_err().to_string();
        assert!(e.contains("trunc.exr"), "{e}");
        // A stack missing one K channel: write a stack, rewrite it without K.0001.
        let p = dir.join("missing.exr");
        let mut c = {
            s.write(&p).unwrap();
            exrio::read(&p).unwrap()
        };
        c.channels.remove("K.0001");
        let channels = c.channels.into_iter().collect();
        let attrs: Vec<(String, Attr)> = c.attrs.into_iter().collect();
        exrio::write(
            &p,
            c.width,
            c.height,
            channels,
            attrs.iter().map(|(n, a)| (n.as_str(), a.clone())).collect(),
        )
        .unwrap();
        let e = SampleStack::read(&p).unwrap_err().to_string();
        assert!(e.contains("K.0001"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn headers_claiming_more_pixels_than_the_file_holds_are_refused() {
        // Fuzz findings (fuzz/corpus/stack/regress-size-*): a mutated data window made the exr
        // crate allocate up to 5e18 bytes and abort; now a message, before any allocation.
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus");
        for f in [
            "stack/regress-size-485.exr",
            "stack/regress-size-8459.exr",
            "ptm/regress-size-9988.ptm.exr",
        ] {
            let e = SampleStack::read(&dir.join(f)).unwrap_err().to_string();
            assert!(
                e.contains("claims") && e.contains("truncated or corrupt"),
                "{f}: {e}"
            );
        }
        let e = ptm_format::Ptm::load(&dir.join("ptm/regress-size-1348.ptm.exr"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("67108862×3 pixels"), "{e}");
    }
}
