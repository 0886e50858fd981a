//! What identifies a bake across the parts of a farm bake: every setting that changes the
//! output, in words. Parts whose words differ never merge. The command fills it from its
//! flags; the words are this type's, so a new output-changing setting is added here, once.
use ptm_format::LightSet;

use super::fingerprint;
use crate::FitOptions;

/// The settings of a bake that change its output (not the thread count, packet tracing or
/// where the swatch file lies: the output is bit-identical for any of those, and the swatch's
/// content hash is recorded separately).
#[derive(Clone, Debug)]
pub struct BakeIdentity<'a> {
    /// Texels of the whole bake (columns, rows).
    pub res: [usize; 2],
    /// Tile size in mesh units.
    pub tile: [f64; 2],
    /// Footprint samples per texel.
    pub spp: u32,
    /// Seed of the sample positions.
    pub seed: u64,
    /// The light set (hashed: directions and names).
    pub lights: &'a LightSet,
    /// Point lights at this distance, or distant lights.
    pub light_distance: Option<f64>,
    /// The streaming fit's options, or none for a sample stack.
    pub fit: Option<&'a FitOptions>,
    /// The companion maps' own settings in words (see `ptm_bake::maps`), or none when the
    /// bake writes no maps. Left out of the words when none, so bakes without maps keep the
    /// words they always had.
    pub maps: Option<String>,
}

impl BakeIdentity<'_> {
    /// The settings in words, as a part records them in `part:settings`.
    pub fn settings(&self) -> String {
        let dirs: Vec<u8> = self
            .lights
            .dirs
            .iter()
            .flat_map(|d| d.iter().flat_map(|c| c.to_le_bytes()))
            .collect();
        let names = self.lights.names.join("\n");
        let light_hash = fingerprint([&dirs[..], names.as_bytes()]);
        let fit = match self.fit {
            None => "stack".to_string(),
            Some(o) => format!(
                "{} link={} uv={} mips={} regularize={:?} tolerance={:e} max-iterations={}",
                o.basis.name(),
                o.link.name(),
                o.uv.name(),
                o.mips,
                o.regularize,
                o.tolerance,
                o.max_iterations
            ),
        };
        let distance = match self.light_distance {
            None => "distant".to_string(),
            Some(r) => format!("{r:e}"),
        };
        let mut words = format!(
            "res={}x{} tile={:e}x{:e} spp={} seed={} lights={} ({light_hash}) light-distance={distance} fit={fit}",
            self.res[0],
            self.res[1],
            self.tile[0],
            self.tile[1],
            self.spp,
            self.seed,
            self.lights.len()
        );
        if let Some(m) = &self.maps {
            words.push_str(" maps=");
            words.push_str(m);
        }
        words
    }
}
