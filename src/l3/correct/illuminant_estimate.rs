//! The scene light estimated from the frame itself, for a frame that carries no illuminant
//! metadata: a neutral (the camera's channel responses to white, up to scale) taken from the
//! mosaic's statistics, matched to the colour temperature whose white response through the
//! table's sensor fits it best (the same match a DNG's AsShotNeutral goes through).
//!
//! The mosaic is read in CFA tiles: each tile gives one value per CFA position, so each tile is
//! a point of the image with every channel. Tiles with a clipped value (at or above
//! [`CLIP_FRACTION`] of the swing) are left out: clipping bends their colour towards the
//! clipped channel. Two statistics of the remaining tiles are offered:
//! - **grey world**: the channel sums over all tiles, matched against the camera's response
//!   to the mean of the training reflectances (a natural scene averages to that, not to white);
//! - **bright tiles**: the channel sums over the brightest [`BRIGHT_FRACTION`] of tiles, a
//!   robust "white patch" (the brightest surfaces are taken as white).
//!
//! Which one works better, and how well either does, is measured by
//! `l3 eval --estimate-illuminant` and reported in `docs/research/illuminant-estimation.md`.

use super::CorrectError;
use crate::camera::Cfa;
use crate::l3::render::{DnScale, Mosaic};
use crate::l3::table::{L3Table, TableError};

/// Tiles with a value at or above this fraction of the swing are left out.
pub const CLIP_FRACTION: f32 = 0.98;
/// The bright-tile statistic uses this fraction of the unclipped tiles, the brightest.
pub const BRIGHT_FRACTION: f64 = 0.02;
/// Fewest unclipped tiles an estimate is made from.
pub const MIN_TILES: usize = 16;

/// Which frame statistic stands for white.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum NeutralStatistic {
    /// The mean of all unclipped tiles.
    GreyWorld,
    /// The mean of the brightest unclipped tiles.
    #[default]
    BrightTiles,
}

impl NeutralStatistic {
    pub fn name(self) -> &'static str {
        match self {
            NeutralStatistic::GreyWorld => "grey-world",
            NeutralStatistic::BrightTiles => "bright-tiles",
        }
    }
}

/// The light estimated from a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct IlluminantEstimate {
    /// The frame's neutral, per channel name, largest 1.
    pub neutral: Vec<(String, f64)>,
    /// The matching colour temperature (kelvin) and the spec to correct with (`cct:K`).
    pub cct: f64,
    pub spec: String,
    /// Root-mean-square log-ratio misfit of the neutral at that temperature.
    pub rms_log_error: f64,
    /// Tiles the statistic used.
    pub tiles: usize,
}

/// The neutral of a mosaic (`width × height`, CFA `cfa` anchored at the top-left pixel,
/// values up to `swing` volts) by `statistic`: per channel name, the largest 1.
pub fn frame_neutral(
    mosaic: &Mosaic,
    width: usize,
    height: usize,
    cfa: &Cfa,
    swing: f64,
    statistic: NeutralStatistic,
) -> Result<(Vec<(String, f64)>, usize), CorrectError> {
    let nc = cfa.n_channels();
    let tiles = tile_channel_means(mosaic, width, height, cfa, swing)?;
    let n_tiles = tiles.len() / nc;
    let tile = |i: usize| &tiles[i * nc..(i + 1) * nc];
    let chosen: Vec<usize> = match statistic {
        NeutralStatistic::GreyWorld => (0..n_tiles).collect(),
        NeutralStatistic::BrightTiles => {
            let n = ((n_tiles as f64 * BRIGHT_FRACTION).ceil() as usize)
                .max(MIN_TILES)
                .min(n_tiles);
            let lum: Vec<f64> = (0..n_tiles).map(|i| tile(i).iter().sum()).collect();
            let mut order: Vec<usize> = (0..n_tiles).collect();
            // the n brightest first (ties by position), in no particular order among themselves
            if n < n_tiles {
                order.select_nth_unstable_by(n, |&a, &b| lum[b].total_cmp(&lum[a]).then(a.cmp(&b)));
            }
            order.truncate(n);
            order.sort_unstable();
            order
        }
    };
    let mut sums = vec![0.0f64; nc];
    for &i in &chosen {
        for (s, v) in sums.iter_mut().zip(tile(i)) {
            *s += v;
        }
    }
    let max = sums.iter().copied().fold(0.0, f64::max);
    if !(max.is_finite() && max > 0.0) || sums.iter().any(|s| *s <= 0.0) {
        return Err(CorrectError::InvalidInput(
            "the frame has no signal in some channel; name the illuminant".into(),
        ));
    }
    let neutral = cfa
        .channel_names
        .iter()
        .cloned()
        .zip(sums.iter().map(|s| s / max))
        .collect();
    Ok((neutral, chosen.len()))
}

/// Per whole CFA tile without a clipped value: the mean of each channel's positions, in volts,
/// `n_channels` values per tile, one tile after another.
fn tile_channel_means(
    mosaic: &Mosaic,
    width: usize,
    height: usize,
    cfa: &Cfa,
    swing: f64,
) -> Result<Vec<f64>, CorrectError> {
    let n = width
        .checked_mul(height)
        .ok_or_else(|| CorrectError::InvalidInput("the frame size overflows".into()))?;
    let len = match mosaic {
        Mosaic::Volts(v) => v.len(),
        Mosaic::Dn { data, .. } => data.len(),
    };
    if len != n {
        return Err(CorrectError::InvalidInput(format!(
            "the mosaic has {len} values for a {width}×{height} frame"
        )));
    }
    let volts_at: Box<dyn Fn(usize) -> f32 + '_> = match mosaic {
        Mosaic::Volts(v) => Box::new(move |i| v[i]),
        Mosaic::Dn { data, black, white } => {
            // the volts a decoded frame holds, to the last bit: on coarse (8-bit) data the
            // brightest tiles tie, and another rounding would choose other tiles
            let dn = DnScale::new(*black, *white, swing).ok_or_else(|| {
                CorrectError::InvalidInput(format!(
                    "white level {white} must exceed black level {black}"
                ))
            })?;
            Box::new(move |i| dn.volts(data[i]))
        }
    };
    let clip = CLIP_FRACTION * swing as f32;
    let nc = cfa.n_channels();
    let mut counts = vec![0usize; nc];
    for &c in &cfa.pattern {
        counts[c] += 1;
    }
    let mut out = Vec::with_capacity((height / cfa.rows) * (width / cfa.cols) * nc);
    let mut means = vec![0.0f64; nc];
    for ty in 0..height / cfa.rows {
        'tile: for tx in 0..width / cfa.cols {
            means.iter_mut().for_each(|m| *m = 0.0);
            for r in 0..cfa.rows {
                for c in 0..cfa.cols {
                    let v = volts_at((ty * cfa.rows + r) * width + tx * cfa.cols + c);
                    if !v.is_finite() || v >= clip {
                        continue 'tile;
                    }
                    let ch = cfa.channel_at(r, c);
                    means[ch] += f64::from(v.max(0.0)) / counts[ch] as f64;
                }
            }
            out.extend_from_slice(&means);
        }
    }
    if out.len() < MIN_TILES * nc {
        return Err(CorrectError::InvalidInput(format!(
            "the frame has {} unclipped CFA tiles; at least {MIN_TILES} are needed to estimate the light (name the illuminant)",
            out.len() / nc
        )));
    }
    Ok(out)
}

impl L3Table {
    /// The colour temperature whose white response, through the table's sensor, best matches
    /// a raw file's neutral (e.g. a DNG's AsShotNeutral, per channel name): see
    /// [`Camera::cct_from_neutral`](crate::camera::Camera::cct_from_neutral). The sensor's
    /// curves are read through `iset` (the built-in data when `None`).
    pub fn illuminant_from_neutral(
        &self,
        neutral: &[(String, f64)],
        iset: Option<&crate::spectral::IsetData>,
    ) -> Result<crate::camera::NeutralMatch, CorrectError> {
        let design = self.sensor_design()?;
        let camera = crate::camera::Camera::new(&design, self.meta.grid, iset)
            .map_err(|e| TableError::Unusable(format!("the table's sensor: {e}")))?;
        camera
            .cct_from_neutral(neutral)
            .map_err(|e| CorrectError::Neutral(e.to_string()))
    }

    /// The light of a frame with no metadata, estimated from the mosaic by `statistic` and
    /// matched to a colour temperature through this table's sensor (its curves read through
    /// `iset`, the built-in data when `None`).
    pub fn estimate_illuminant(
        &self,
        mosaic: &Mosaic,
        width: usize,
        height: usize,
        statistic: NeutralStatistic,
        iset: Option<&crate::spectral::IsetData>,
    ) -> Result<IlluminantEstimate, CorrectError> {
        let (neutral, tiles) = frame_neutral(
            mosaic,
            width,
            height,
            &self.meta.cfa,
            self.meta.voltage_swing,
            statistic,
        )?;
        let m = match statistic {
            NeutralStatistic::BrightTiles => self.illuminant_from_neutral(&neutral, iset)?,
            NeutralStatistic::GreyWorld => {
                let grid = self.meta.grid;
                let camera = crate::camera::Camera::new(&self.sensor_design()?, grid, iset)
                    .map_err(|e| TableError::Unusable(format!("the table's sensor: {e}")))?;
                camera
                    .cct_from_surface(&neutral, &mean_natural_surface(&grid, iset)?)
                    .map_err(|e| CorrectError::Neutral(e.to_string()))?
            }
        };
        Ok(IlluminantEstimate {
            neutral,
            cct: m.cct,
            spec: m.spec(),
            rms_log_error: m.rms_log_error,
            tiles,
        })
    }
}

/// Where a frame's light came from, when the request named none.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IlluminantSource {
    /// The frame's metadata: a sidecar's illuminant or a DNG's AsShotNeutral.
    Metadata,
    /// Estimated from the mosaic.
    Estimated,
    /// D65: no metadata and too little unclipped signal to estimate.
    Default,
}

impl IlluminantSource {
    /// The name used in headers and reports: `metadata`, `estimated`, `default`.
    pub fn name(self) -> &'static str {
        match self {
            IlluminantSource::Metadata => "metadata",
            IlluminantSource::Estimated => "estimated",
            IlluminantSource::Default => "default",
        }
    }

    /// Where the light came from, in words: `the frame's metadata`, `an estimate from the
    /// frame`, `the default`.
    pub fn describe(self) -> &'static str {
        match self {
            IlluminantSource::Metadata => "the frame's metadata",
            IlluminantSource::Estimated => "an estimate from the frame",
            IlluminantSource::Default => "the default",
        }
    }
}

/// What a frame says about its light, beside the mosaic.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameMetadata<'a> {
    /// An illuminant spec (a sidecar's `illuminant`).
    pub illuminant: Option<&'a str>,
    /// A recorded neutral per channel name (a DNG's AsShotNeutral).
    pub neutral: Option<&'a [(String, f64)]>,
}

impl L3Table {
    /// The light of a frame whose request named none: the metadata's illuminant, else the
    /// colour temperature matching its neutral, else an estimate from the mosaic
    /// ([`NeutralStatistic::default`]), else D65. Returns the illuminant spec and its source.
    /// A neutral that cannot be matched is an error (the caller should name the light).
    pub fn frame_illuminant(
        &self,
        metadata: FrameMetadata,
        mosaic: &Mosaic,
        width: usize,
        height: usize,
        iset: Option<&crate::spectral::IsetData>,
    ) -> Result<(String, IlluminantSource), CorrectError> {
        if let Some(spec) = metadata.illuminant {
            return Ok((spec.to_string(), IlluminantSource::Metadata));
        }
        if let Some(n) = metadata.neutral {
            let m = self.illuminant_from_neutral(n, iset)?;
            return Ok((m.spec(), IlluminantSource::Metadata));
        }
        Ok(
            match self.estimate_illuminant(mosaic, width, height, NeutralStatistic::default(), iset)
            {
                Ok(e) => (e.spec, IlluminantSource::Estimated),
                Err(_) => ("D65".to_string(), IlluminantSource::Default),
            },
        )
    }
}

/// The mean of the training reflectances (natural objects, paints, Munsell and CES samples):
/// the grey a grey-world scene averages to.
fn mean_natural_surface(
    grid: &crate::spectral::WavelengthGrid,
    iset: Option<&crate::spectral::IsetData>,
) -> Result<crate::spectral::Spectrum, CorrectError> {
    let set = crate::scene::training_reflectances(grid, iset)
        .map_err(|e| CorrectError::InvalidInput(e.to_string()))?;
    let mut mean = vec![0.0; grid.len()];
    for (_, r) in &set {
        for (m, v) in mean.iter_mut().zip(r.values()) {
            *m += v / set.len() as f64;
        }
    }
    crate::spectral::Spectrum::new(*grid, mean).map_err(CorrectError::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rgbw() -> Cfa {
        Cfa::parse("RG/WB").unwrap()
    }

    /// A frame of tiles whose channel values are `colour` scaled by a per-tile brightness.
    fn frame(colour: [f32; 4], w: usize, h: usize, bright: impl Fn(usize) -> f32) -> Vec<f32> {
        let cfa = rgbw();
        let mut v = vec![0.0; w * h];
        for y in 0..h {
            for x in 0..w {
                let tile = (y / 2) * (w / 2) + x / 2;
                v[y * w + x] = colour[cfa.channel_at(y % 2, x % 2)] * bright(tile);
            }
        }
        v
    }

    #[test]
    fn a_uniform_frame_gives_its_own_colour_by_either_statistic() {
        let colour = [0.2, 0.4, 0.8, 0.1];
        let v = frame(colour, 32, 32, |t| 0.5 + (t % 7) as f32 * 0.1);
        for s in [NeutralStatistic::GreyWorld, NeutralStatistic::BrightTiles] {
            let (n, tiles) = frame_neutral(&Mosaic::Volts(&v), 32, 32, &rgbw(), 1.8, s).unwrap();
            let names = &rgbw().channel_names;
            for (i, (name, val)) in n.iter().enumerate() {
                assert_eq!(name, &names[i]);
                assert!(
                    (val - f64::from(colour[i] / 0.8)).abs() < 1e-6,
                    "{s:?} {n:?}"
                );
            }
            assert!(tiles >= MIN_TILES);
        }
    }

    #[test]
    fn clipped_tiles_are_left_out() {
        // the brightest tiles clip W: they must not pull the neutral
        let colour = [0.2, 0.4, 0.8, 0.1];
        let v = frame(colour, 32, 32, |t| if t % 5 == 0 { 10.0 } else { 1.0 });
        let (n, _) = frame_neutral(
            &Mosaic::Volts(&v),
            32,
            32,
            &rgbw(),
            1.8,
            NeutralStatistic::BrightTiles,
        )
        .unwrap();
        assert!((n[0].1 - 0.25).abs() < 1e-6, "{n:?}");
    }

    #[test]
    fn integer_frames_are_read_through_their_levels() {
        let data: Vec<u16> = (0..64 * 64)
            .map(|i| if (i / 64) % 2 == 0 { 1064 } else { 2064 })
            .collect();
        let m = Mosaic::Dn {
            data: &data,
            black: 64,
            white: 4095,
        };
        let (n, _) = frame_neutral(&m, 64, 64, &rgbw(), 1.8, NeutralStatistic::GreyWorld).unwrap();
        // rows 0 (R, G) get 1000 DN over black, rows 1 (W, B) 2000
        assert!(
            (n[0].1 - 0.5).abs() < 1e-6 && (n[2].1 - 1.0).abs() < 1e-6,
            "{n:?}"
        );
    }

    /// A DN frame gives the neutral its decoded volts give, to the bit, even on 8-bit data
    /// where many tiles tie on brightness (the service estimates from DN, the CLI from volts).
    #[test]
    fn dn_and_decoded_volts_give_the_same_neutral() {
        let (w, h) = (96, 64);
        let mut state = 0x2545_f491_u32;
        let data: Vec<u16> = (0..w * h)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                (state % 256) as u16
            })
            .collect();
        for (black, white) in [(0u16, 255u16), (16, 255), (0, 100)] {
            let frame = crate::io::RawFrame::new(w, h, data.clone()).unwrap();
            let meta = crate::io::RawMeta::new(w, h, "RG/WB", black, white, 1.8);
            let volts = frame.to_volts(&meta).unwrap();
            let dn = Mosaic::Dn {
                data: &data,
                black,
                white,
            };
            let s = NeutralStatistic::BrightTiles;
            assert_eq!(
                frame_neutral(&dn, w, h, &rgbw(), 1.8, s).unwrap(),
                frame_neutral(&Mosaic::Volts(&volts), w, h, &rgbw(), 1.8, s).unwrap(),
                "black {black}, white {white}"
            );
        }
    }

    #[test]
    fn frames_without_enough_signal_are_refused() {
        let cfa = rgbw();
        let dark = vec![0.0f32; 32 * 32];
        assert!(
            frame_neutral(
                &Mosaic::Volts(&dark),
                32,
                32,
                &cfa,
                1.8,
                NeutralStatistic::GreyWorld
            )
            .is_err()
        );
        let clipped = vec![1.8f32; 32 * 32];
        assert!(
            frame_neutral(
                &Mosaic::Volts(&clipped),
                32,
                32,
                &cfa,
                1.8,
                NeutralStatistic::BrightTiles
            )
            .is_err()
        );
        let short = vec![0.5f32; 10];
        assert!(
            frame_neutral(
                &Mosaic::Volts(&short),
                32,
                32,
                &cfa,
                1.8,
                NeutralStatistic::GreyWorld
            )
            .is_err()
        );
    }
}
