use std::path::PathBuf;

use clap::Args;

use super::{Cli, CliError, iset, load_sensor, write_file};
use crate::camera::{Camera, Exposure, NoiseSwitches, simulate};
use crate::io::{
    DngWriteInfo, IoError, PngCompression, RawFrame, RawMeta, exif_light_source, write_dng,
    write_png_gray16, write_png_rgb8, write_raw, write_tiff_f32_rgb,
};
use crate::l3::render::{WhiteLevel, white_y, xyz_to_srgb8};
use crate::scene::{SceneKind, SceneOptions, training_reflectances};
use crate::spectral::{IlluminantSpec, IsetData, NamedSpd, WavelengthGrid};

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// macbeth | natural100 | dead-leaves | uniform | grey-ramp | edge (a slanted edge) | image:PATH
    #[arg(long, default_value = "macbeth")]
    pub scene: String,
    /// D65 | A | F11 | Tungsten | cct:3200 | csv:PATH[:COLUMN]
    #[arg(long, default_value = "D65")]
    pub illuminant: String,
    /// Sensor: a design TOML or a catalogue name (`l3 sensors`; default: the paper's RGBW sensor).
    #[arg(long)]
    pub sensor: Option<PathBuf>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder.
    #[arg(long, default_value = "out/sim")]
    pub out: PathBuf,
    /// `auto` (brightest region at 95 % of the swing) or seconds.
    #[arg(long, default_value = "auto")]
    pub exposure: String,
    /// Mean scene luminance, cd/m².
    #[arg(long, default_value_t = 100.0)]
    pub luminance: f64,
    /// Simulate without noise.
    #[arg(long)]
    pub no_noise: bool,
}

pub fn parse_exposure(s: &str) -> Result<Exposure, CliError> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(Exposure::Auto {
            target_fraction: 0.95,
        });
    }
    match s.parse::<f64>() {
        Ok(t) if t.is_finite() && t > 0.0 && t <= 60.0 => Ok(Exposure::Seconds(t)),
        _ => Err(CliError::Usage(format!(
            "--exposure '{s}': expected 'auto' or seconds in (0, 60]"
        ))),
    }
}

pub fn run(cli: &Cli, a: &SimulateArgs) -> Result<(), CliError> {
    let iset = iset(&cli.iset_dir)?;
    let design = load_sensor(&a.sensor, iset.as_ref())?;
    let grid = WavelengthGrid::default();
    let camera = Camera::new(&design, grid, iset.as_ref())?;
    let kind: SceneKind = a.scene.parse()?;
    let named = IlluminantSpec::parse(&a.illuminant)?.resolve(iset.as_ref())?;
    if !(a.luminance.is_finite() && a.luminance > 0.0) {
        return Err(CliError::Usage(format!(
            "--luminance {} must be positive",
            a.luminance
        )));
    }
    let opts = SceneOptions::from_samples(grid, &named.spd, named.name.clone())?
        .with_mean_luminance(a.luminance);
    let scene = kind.build(iset.as_ref(), &opts, a.seed)?;
    let noise = if a.no_noise {
        NoiseSwitches::none()
    } else {
        NoiseSwitches::all()
    };
    let started = std::time::Instant::now();
    let cap = simulate(
        &camera,
        &scene,
        parse_exposure(&a.exposure)?,
        &noise,
        a.seed,
    )?;
    let secs = started.elapsed().as_secs_f64();
    let auto = a.exposure.trim().eq_ignore_ascii_case("auto");
    if auto && cap.exposure_s >= crate::camera::MAX_AUTO_EXPOSURE_S {
        eprintln!(
            "warning: auto-exposure stopped at its longest, {} s: the sensor '{}' collects too \
             little light from this scene to reach 95 % of its swing (its curves' scale?); the \
             frame is mostly noise",
            crate::camera::MAX_AUTO_EXPOSURE_S,
            design.name
        );
    }
    let (h, w) = cap.volts.dim();
    let swing = design.voltage_swing_v;
    let volts = cap.volts.as_slice().unwrap_or(&[]);
    let mut meta = RawMeta::new(w, h, cap.cfa.to_string(), 0, 65535, swing);
    meta.illuminant = Some(named.name.clone());
    meta.exposure_s = Some(cap.exposure_s);
    meta.seed = Some(a.seed);
    meta.sensor = Some(design.name.clone());
    let frame = RawFrame::from_volts(volts, w, h, &meta)?;
    std::fs::create_dir_all(&a.out).map_err(|source| CliError::File {
        path: a.out.display().to_string(),
        source,
    })?;
    let raw_paths = write_raw(&a.out.join("mosaic.raw"), &frame, &meta)?;
    write_png_gray16(&a.out.join("mosaic.png"), &frame)?;
    // the same mosaic as DNG, with the camera's white response under the light as
    // AsShotNeutral (CFAs of R, G, B and W only)
    let dng = dng_info(&camera, &design.name, &named, &grid, iset.as_ref())?;
    let dng_note = match write_dng(&a.out.join("mosaic.dng"), &frame, &meta, &dng) {
        Ok(()) => "mosaic.dng, ".to_string(),
        Err(IoError::InvalidMeta(why)) => format!("no mosaic.dng ({why}), "),
        Err(e) => return Err(e.into()),
    };
    // a ColorChecker's truth as the chart evaluation takes it, for `l3 eval --colorchecker
    // --reference truth.csv`
    let truth_note = if matches!(kind, SceneKind::Macbeth) {
        let ideal = crate::eval::ideal_d65_patch_means(&camera, &scene)?;
        let csv = crate::eval::colorchecker::simulated_truth_csv(&ideal)?;
        write_file(&a.out.join("truth.csv"), csv.as_bytes())?;
        "truth.csv, "
    } else {
        ""
    };
    let xyz = cap.ideal_xyz.as_slice().unwrap_or(&[]);
    write_tiff_f32_rgb(&a.out.join("ideal_xyz.tiff"), w, h, xyz)?;
    let wy = white_y(xyz, w, h, WhiteLevel::Auto);
    write_png_rgb8(
        &a.out.join("preview.png"),
        w,
        h,
        &xyz_to_srgb8(xyz, wy),
        PngCompression::Default,
    )?;
    println!(
        "simulated {} ({}×{}) under {} through {}: exposure {:.4} ms, {:.1} ms",
        scene.name,
        w,
        h,
        named.name,
        design.name,
        cap.exposure_s * 1e3,
        secs * 1e3
    );
    println!(
        "wrote {} (+ .json), {dng_note}mosaic.png, ideal_xyz.tiff, {truth_note}preview.png in {}",
        raw_paths.raw.display(),
        a.out.display()
    );
    Ok(())
}

/// What the DNG twin of the mosaic records: the sensor's name, the camera's white response
/// under the light, the light's EXIF code, and the XYZ → camera matrix fitted on the
/// training reflectances under it.
fn dng_info(
    camera: &Camera,
    sensor: &str,
    named: &NamedSpd,
    grid: &WavelengthGrid,
    iset: Option<&IsetData>,
) -> Result<DngWriteInfo, CliError> {
    Ok(DngWriteInfo {
        camera_model: Some(sensor.to_string()),
        as_shot_neutral: Some(camera.white_neutral(&named.spd)?),
        calibration_illuminant: exif_light_source(&named.name),
        color_matrix: Some(
            camera
                .cfa()
                .channel_names
                .iter()
                .cloned()
                .zip(
                    camera.xyz_to_camera_matrix(
                        &named.spd,
                        &training_reflectances(grid, iset)?
                            .into_iter()
                            .map(|(_, s)| s)
                            .collect::<Vec<_>>(),
                    )?,
                )
                .collect(),
        ),
    })
}
