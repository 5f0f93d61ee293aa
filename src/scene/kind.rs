//! Scene kinds as the command line names them, with default builders.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use crate::spectral::{Extrapolation, IsetData, Spectrum};

use super::chart::macbeth;
use super::dead_leaves::{DeadLeavesParams, dead_leaves};
use super::image_lift::from_srgb_file;
use super::natural100::{NATURAL100_PATCH_PX, ces_samples, natural100_chart};
use super::simple::{grey_ramp, uniform};
use super::slanted_edge::{EDGE_SIZE, SlantedEdgeParams, slanted_edge};
use super::{Scene, SceneError, SceneOptions};

/// A scene kind: `macbeth | natural100 | dead-leaves | uniform | grey-ramp | edge |
/// image:PATH` (case-insensitive; `_` may replace `-`, `gray` `grey`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SceneKind {
    Macbeth,
    Natural100,
    DeadLeaves,
    Uniform,
    GreyRamp,
    /// A grey-on-grey edge 5° from vertical under a white strip ([`slanted_edge`]).
    SlantedEdge,
    Image(PathBuf),
}

/// The name the CLI brief uses.
pub type ScenesKind = SceneKind;

/// Patch size of the default Macbeth chart, pixels.
pub const MACBETH_PATCH_PX: usize = 32;
/// Size of the default dead-leaves, uniform and ramp scenes.
pub const DEFAULT_TEXTURE_SIZE: (usize, usize) = (256, 256);

impl FromStr for SceneKind {
    type Err = SceneError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim();
        if let Some(p) = t.strip_prefix("image:") {
            if p.is_empty() {
                return Err(SceneError::Invalid("expected image:PATH".into()));
            }
            return Ok(Self::Image(PathBuf::from(p)));
        }
        let k = t
            .to_ascii_lowercase()
            .replace('_', "-")
            .replace("gray", "grey");
        Ok(match k.as_str() {
            "macbeth" | "mcc" => Self::Macbeth,
            "natural100" | "natural-100" => Self::Natural100,
            "dead-leaves" | "deadleaves" => Self::DeadLeaves,
            "uniform" => Self::Uniform,
            "grey-ramp" | "ramp" => Self::GreyRamp,
            "edge" | "slanted-edge" => Self::SlantedEdge,
            _ => {
                return Err(SceneError::Invalid(format!(
                    "unknown scene '{s}' (expected macbeth, natural100, dead-leaves, uniform, grey-ramp, edge or image:PATH)"
                )));
            }
        })
    }
}

impl fmt::Display for SceneKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Macbeth => f.write_str("macbeth"),
            Self::Natural100 => f.write_str("natural100"),
            Self::DeadLeaves => f.write_str("dead-leaves"),
            Self::Uniform => f.write_str("uniform"),
            Self::GreyRamp => f.write_str("grey-ramp"),
            Self::SlantedEdge => f.write_str("edge"),
            Self::Image(p) => write!(f, "image:{}", p.display()),
        }
    }
}

impl SceneKind {
    /// Build the kind with default parameters (`iset` `None`: the built-in
    /// spectral data): Macbeth with 32 px patches; Natural-100 with 24 px
    /// patches; 256 × 256 dead leaves of the 99 CES reflectances
    /// with `seed`; a 256 × 256 uniform 50 % grey; a 256 × 256 ramp of 16
    /// steps; a 128 × 128 slanted edge; an sRGB image file.
    pub fn build(
        &self,
        iset: Option<&IsetData>,
        opts: &SceneOptions,
        seed: u64,
    ) -> Result<Scene, SceneError> {
        let (rows, cols) = DEFAULT_TEXTURE_SIZE;
        match self {
            Self::Macbeth => macbeth(IsetData::or_built_in(iset), opts, MACBETH_PATCH_PX),
            Self::Natural100 => {
                natural100_chart(IsetData::or_built_in(iset), opts, NATURAL100_PATCH_PX)
            }
            Self::DeadLeaves => {
                let set: Vec<Spectrum> = ces_samples()
                    .iter()
                    .map(|s| s.samples.resample(&opts.grid, Extrapolation::Hold))
                    .collect();
                dead_leaves(opts, &set, &DeadLeavesParams::new(rows, cols, seed))
            }
            Self::Uniform => uniform(opts, &Spectrum::constant(opts.grid, 0.5), rows, cols),
            Self::GreyRamp => grey_ramp(opts, rows, cols, 16),
            Self::SlantedEdge => slanted_edge(opts, &SlantedEdgeParams::new(EDGE_SIZE, EDGE_SIZE)),
            Self::Image(p) => from_srgb_file(opts, p),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_prints() {
        for (s, k) in [
            ("macbeth", SceneKind::Macbeth),
            ("Natural100", SceneKind::Natural100),
            ("dead_leaves", SceneKind::DeadLeaves),
            ("uniform", SceneKind::Uniform),
            ("gray-ramp", SceneKind::GreyRamp),
            ("slanted_edge", SceneKind::SlantedEdge),
            ("edge", SceneKind::SlantedEdge),
            ("image:a/b.png", SceneKind::Image("a/b.png".into())),
        ] {
            let got: SceneKind = s.parse().unwrap();
            assert_eq!(got, k);
            assert_eq!(got.to_string().parse::<SceneKind>().unwrap(), k);
        }
        assert!("image:".parse::<SceneKind>().is_err());
        assert!("checkerboard".parse::<SceneKind>().is_err());
    }
}
