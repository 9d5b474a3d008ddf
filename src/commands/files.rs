//! Commands about files, devices and the config: `export`, `import`, `devices`, `config`.

use crate::cli::{self, ConfigAction};
use anyhow::{bail, Result};
use impactcam::config::Config;
use std::path::PathBuf;

/// `impactcam export`: a session as a TIFF stack, an MRAW + CIH or an FMF.
pub(crate) fn export(
    session: PathBuf,
    out: Option<PathBuf>,
    format: Option<cli::ExportFormatArg>,
    tiff: Option<PathBuf>,
) -> Result<i32> {
    use impactcam::footage::import::ExportFormat;
    let (format, out) = match (tiff, format, out) {
        (Some(t), _, _) => (ExportFormat::Tiff, t),
        (None, Some(f), Some(o)) => (
            match f {
                cli::ExportFormatArg::Tiff => ExportFormat::Tiff,
                cli::ExportFormatArg::Mraw => ExportFormat::Mraw,
                cli::ExportFormatArg::Fmf => ExportFormat::Fmf,
            },
            o,
        ),
        _ => bail!("give --format tiff|mraw|fmf and the file to write (or --tiff OUT.tif)"),
    };
    let done = impactcam::footage::import::export(&session, format, &out)?;
    let n = done.frames;
    if let Some(c) = &done.caveat {
        eprintln!("warning: {c}");
    }
    if format == ExportFormat::Mraw {
        println!(
            "wrote {n} frames to {} and {}",
            out.with_extension("mraw").display(),
            out.with_extension("cih").display()
        );
    } else {
        println!("wrote {n} frames to {}", out.display());
    }
    Ok(0)
}

/// `impactcam import`: another camera's file as a session.
pub(crate) fn import(file: PathBuf, out: PathBuf, config: Option<PathBuf>) -> Result<i32> {
    let cfg = config.as_deref().map(Config::load_unchecked).transpose()?;
    let done = impactcam::footage::import::import(&file, &out, cfg.as_ref())?;
    println!(
        "imported {} frames ({}, {}×{} px, {} frames/s) into {}",
        done.frames,
        done.kind,
        done.width,
        done.height,
        done.frame_rate_hz,
        done.session.display()
    );
    Ok(0)
}

/// `impactcam devices`: the cameras and serial ports this machine sees.
pub(crate) fn devices() -> Result<i32> {
    println!("cameras:");
    for line in impactcam::camera::list() {
        println!("  {line}");
    }
    println!("serial ports (relay modules):");
    match serialport::available_ports() {
        Ok(ports) if ports.is_empty() => println!("  none found"),
        Ok(ports) => {
            for p in ports {
                println!("  {}  {:?}", p.port_name, p.port_type);
            }
        }
        Err(e) => println!("  cannot list: {e}"),
    }
    Ok(0)
}

/// `impactcam config check|default`.
pub(crate) fn config(action: ConfigAction) -> Result<i32> {
    match action {
        ConfigAction::Check { file } => {
            let cfg = Config::load(&file)?;
            println!(
                "{}: valid ({} camera {}×{} {} at {} Hz, {} trigger)",
                file.display(),
                format!("{:?}", cfg.camera.backend).to_lowercase(),
                cfg.camera.width,
                cfg.camera.height,
                cfg.camera.pixel_format.name(),
                cfg.camera.frame_rate_hz,
                format!("{:?}", cfg.trigger.backend).to_lowercase()
            );
            Ok(0)
        }
        ConfigAction::Default => {
            print!("{}", impactcam::config::DEFAULT_TOML);
            Ok(0)
        }
    }
}
