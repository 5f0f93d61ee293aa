//! `l3 demosaic`: a mosaic through the conventional pipelines' demosaics (and the ISP's
//! denoiser), to 32-bit float TIFF; and the ISP options `l3 eval --method isp` takes.

use std::path::PathBuf;

use clap::Args;

use super::{CliError, iset, load_sensor};
use crate::baseline::{ColourMatrix, DemosaicMethod, DenoiseParams, Isp, NoiseProfile, demosaic};
use crate::camera::{Camera, Cfa};
use crate::io::{DecodedMosaic, Limits, read_mosaic, write_tiff_f32_rgb, write_tiff_gray_f32};
use crate::spectral::WavelengthGrid;

#[derive(Args, Debug)]
pub struct DemosaicArgs {
    /// The mosaic: any file `l3 render` reads (PGM, PNG, TIFF, DNG, .raw with its sidecar).
    /// Integer samples are taken as they are (volts when a sidecar gives the scale); float
    /// samples as they are.
    #[arg(long = "in")]
    pub input: PathBuf,
    /// The CFA, e.g. `RG/GB` (default: the sidecar's, else the sensor's).
    #[arg(long)]
    pub cfa: Option<String>,
    /// `bilinear`, `malvar` (Bayer only), `gradient` (2×2 tiles; bilinear beyond), `auto`
    /// (Malvar on Bayer, gradient otherwise) or `isp` (auto, then the ISP's denoiser with the
    /// sensor's noise model).
    #[arg(long, default_value = "auto")]
    pub method: String,
    /// The sensor whose noise model `--method isp` denoises with (a design TOML or a
    /// catalogue name; default: the paper's RGBW sensor).
    #[arg(long)]
    pub sensor: Option<PathBuf>,
    #[command(flatten)]
    pub isp: IspArgs,
    /// Run it this many times and print the rate (Mpix/s) of the fastest.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeat: u32,
    /// Output: a 32-bit float TIFF, RGB in R, G, B order for a CFA with channels R, G and B
    /// only; otherwise one grey float TIFF per channel, `<stem>-<channel>.tiff`.
    #[arg(long)]
    pub out: PathBuf,
    /// Largest frame read (width × height, stored pixels of a DNG); the default takes every
    /// catalogue camera (the largest, the Fujifilm GFX 100, stores 102 MP).
    #[arg(long, value_name = "PIXELS", default_value_t = Limits::default().max_pixels)]
    pub max_pixels: usize,
}

/// The strong ISP's options (`l3 eval --method isp`, `l3 demosaic --method isp`).
#[derive(Args, Debug, Clone)]
pub struct IspArgs {
    /// The ISP's demosaic: auto (Malvar on Bayer, the gradient-corrected bilinear on other
    /// 2×2 CFAs, bilinear beyond), malvar, gradient or bilinear.
    #[arg(long, default_value = "auto")]
    pub isp_demosaic: String,
    /// The gradient-corrected demosaic's gain (0 is bilinear).
    #[arg(long, default_value_t = crate::baseline::DEFAULT_GRADIENT_GAIN)]
    pub isp_gradient_gain: f32,
    /// The ISP's denoiser: `off`, or `LUMA_RADIUS,LUMA_STRENGTH,CHROMA_RADIUS,CHROMA_STRENGTH`
    /// (radii in pixels, strengths multiplying the noise variance). Default: the measured best.
    #[arg(long)]
    pub isp_denoise: Option<String>,
}

impl IspArgs {
    /// The ISP with `matrix`, denoising (unless `off`) by `camera`'s noise model (at each
    /// capture's exposure when evaluated on a chart).
    pub fn build(&self, matrix: ColourMatrix, camera: &Camera) -> Result<Isp, CliError> {
        let mut denoise = DenoiseParams::default();
        let mut on = true;
        match self.isp_denoise.as_deref() {
            None => {}
            Some("off") => on = false,
            Some(s) => {
                let v: Vec<f32> = s
                    .split(',')
                    .map(|x| x.trim().parse::<f32>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| CliError::Usage(format!("--isp-denoise '{s}': {e}")))?;
                let ok = v.len() == 4 && v.iter().all(|x| x.is_finite() && *x >= 0.0);
                if !ok || v[0] > 64.0 || v[2] > 64.0 {
                    return Err(CliError::Usage(format!(
                        "--isp-denoise '{s}': expected off or four non-negative numbers, radii at most 64"
                    )));
                }
                denoise = DenoiseParams {
                    luma_radius: v[0] as usize,
                    luma_strength: v[1],
                    chroma_radius: v[2] as usize,
                    chroma_strength: v[3],
                };
            }
        }
        let mut isp = Isp::new(matrix, on.then(|| NoiseProfile::new(camera, 0.0)));
        isp.demosaic = self.isp_demosaic.parse()?;
        isp.gradient_gain = self.isp_gradient_gain;
        isp.denoise = denoise;
        Ok(isp)
    }
}

pub fn run(cli: &super::Cli, a: &DemosaicArgs) -> Result<(), CliError> {
    let ext = a.out.extension().and_then(|e| e.to_str()).unwrap_or("");
    if !matches!(ext.to_ascii_lowercase().as_str(), "tiff" | "tif") {
        return Err(CliError::Usage(format!(
            "--out {}: demosaic writes 32-bit float TIFF; use .tiff",
            a.out.display()
        )));
    }
    let iset = iset(&cli.iset_dir)?;
    let design = load_sensor(&a.sensor, iset.as_ref())?;
    let loaded = read_mosaic(&a.input, &Limits::with_max_pixels(a.max_pixels))?;
    let (width, height) = loaded.mosaic.dims();
    let volts: Vec<f32> = match (&loaded.mosaic, &loaded.meta) {
        (DecodedMosaic::U16(f), Some(meta)) => f.to_volts(meta)?,
        (DecodedMosaic::U16(f), None) => f.data.iter().map(|&v| v as f32).collect(),
        (DecodedMosaic::F32 { data, .. }, _) => data.clone(),
    };
    let cfa_text = a
        .cfa
        .clone()
        .or_else(|| loaded.meta.as_ref().map(|m| m.cfa.clone()))
        .unwrap_or_else(|| design.cfa.to_string());
    let cfa = Cfa::parse(&cfa_text)?;
    let camera = Camera::new(&design, WavelengthGrid::default(), iset.as_ref())?;
    let nc = cfa.n_channels();
    let run: Result<Isp, DemosaicMethod> = if a.method == "isp" {
        let identity = ColourMatrix {
            m: vec![[0.0; 3]; nc],
            n_channels: nc,
        };
        Ok(a.isp.build(identity, &camera)?)
    } else {
        Err(a
            .method
            .parse()
            .map_err(|e| CliError::Usage(format!("--method: {e}")))?)
    };
    let mut best = f64::INFINITY;
    let mut out = Vec::new();
    for _ in 0..a.repeat {
        let t = std::time::Instant::now();
        out = match &run {
            Ok(isp) => isp.channels(&volts, width, height, &cfa)?,
            Err(m) => demosaic(&volts, width, height, &cfa, *m, a.isp.isp_gradient_gain)?,
        };
        best = best.min(t.elapsed().as_secs_f64());
    }
    let mpix = (width * height) as f64 / 1e6;
    println!(
        "{} {width}×{height} ({cfa}): {:.1} ms, {:.1} Mpix/s (fastest of {})",
        a.method,
        best * 1e3,
        mpix / best,
        a.repeat
    );
    write_channels(&a.out, &cfa, width, height, &out)
}

/// The demosaicked channels to float TIFF(s) (see [`DemosaicArgs::out`]).
fn write_channels(
    out: &std::path::Path,
    cfa: &Cfa,
    width: usize,
    height: usize,
    data: &[f32],
) -> Result<(), CliError> {
    let nc = cfa.n_channels();
    let rgb: Option<Vec<usize>> = ["R", "G", "B"]
        .iter()
        .map(|n| cfa.channel_index(n))
        .collect();
    if let (Some(idx), 3) = (rgb, nc) {
        let px: Vec<f32> = data
            .chunks_exact(3)
            .flat_map(|p| idx.iter().map(|&i| p[i]).collect::<Vec<_>>())
            .collect();
        write_tiff_f32_rgb(out, width, height, &px)?;
        println!("wrote {}", out.display());
        return Ok(());
    }
    let stem = out.with_extension("");
    for (k, name) in cfa.channel_names.iter().enumerate() {
        let plane: Vec<f32> = data.iter().skip(k).step_by(nc).copied().collect();
        let path = PathBuf::from(format!("{}-{name}.tiff", stem.display()));
        write_tiff_gray_f32(&path, width, height, &plane)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
