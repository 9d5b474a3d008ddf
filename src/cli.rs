//! The command line's arguments: every command and option, with the help text `--help` shows.

use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "impactcam",
    version,
    about = "Sphere-collision experiments: camera, relay, recording, and e/β/ψ"
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
    /// Log lines on stderr: `human` or `json` (one object per line, for journald or a log
    /// collector). Default: $IMPACTCAM_LOG_FORMAT, else human.
    #[arg(long, global = true, value_enum)]
    pub(crate) log_format: Option<LogFormat>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum LogFormat {
    Human,
    Json,
}

#[derive(Subcommand)]
pub(crate) enum Command {
    /// One experiment: arm the camera, fire the relay, record, analyse, print the result.
    Run {
        /// Config file (TOML); without it, the embedded default (the simulated lab).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print the report as JSON on stdout instead of the summary.
        #[arg(long)]
        json: bool,
    },
    /// Arm, fire and record only (no analysis).
    Capture {
        /// Config file (TOML); without it, the embedded default (the simulated lab).
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Re-analyse recorded sessions with their own configs; each report must equal the recorded
    /// one.
    Replay {
        /// Session directories to analyse again, or directories of them (a campaign, a
        /// sessions directory).
        #[arg(required = true)]
        sessions: Vec<PathBuf>,
        /// Print the report as JSON on stdout instead of the summary (one session only).
        #[arg(long)]
        json: bool,
        /// Only the sessions at positions i, i + n, i + 2n, … of the sorted list: one task of
        /// a cluster's array job (`--shard $SLURM_ARRAY_TASK_ID/16`); `impactcam fit` is the
        /// reduce.
        #[arg(long, value_name = "i/n")]
        shard: Option<impactcam::batch::Shard>,

        /// Threads to analyse with (default: every core). The report is the same, bit for
        /// bit, whatever the number.
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
        jobs: Option<u16>,
    },
    /// Find each view's map (scale, roll, the mirror's tilt) from a recording of a collision,
    /// knowing only the sphere diameter, the frame rate and g: prints the [geometry] TOML with
    /// each parameter's uncertainty, and draws the regions and axes on the impact frame (PNG).
    Calibrate {
        /// Session directories or multi-page greyscale TIFF stacks of one rig: their flights are
        /// fitted together (more flights, a better roll and tilt).
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        /// The config giving the diameter, frame rate, g and the provisional geometry (regions,
        /// rough scales, the mirror's side); a session uses its own without it.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Write the TOML here (and the PNG beside it, .png) instead of printing it.
        #[arg(long)]
        out: Option<PathBuf>,
        /// An image (TIFF, PNG, or a session's first frame) of a dot-grid target held in the
        /// plane of collision, filling the direct view: the lens's distortion is taken from it
        /// instead of from the flights.
        #[arg(long, requires = "grid_pitch_mm")]
        grid: Option<PathBuf>,
        /// The grid's dot spacing, mm.
        #[arg(long)]
        grid_pitch_mm: Option<f64>,
    },
    /// Analyse a session, a multi-page greyscale TIFF recorded elsewhere, or (--tracks) centres
    /// digitised in other software.
    Analyze {
        /// A session directory or a multi-page greyscale TIFF stack; or several sessions, or
        /// directories of them (a campaign, a sessions directory), each analysed with its own
        /// config (or --config) and its report.json written into it.
        #[arg(required_unless_present = "tracks", conflicts_with = "tracks")]
        paths: Vec<PathBuf>,
        /// CSV of digitised centres: frame,sphere,view,u,v[,time_s].
        #[arg(long)]
        tracks: Option<PathBuf>,
        /// The config to analyse with. A session uses its own recorded config without it; a
        /// TIFF stack or --tracks needs one.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print the report as JSON on stdout instead of the summary.
        #[arg(long)]
        json: bool,
        /// Where report.json goes (default: beside the input).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Replace a session's recorded report.json with one from another --config (without
        /// this, that is refused: `replay` compares against the recorded report).
        #[arg(long)]
        overwrite: bool,
        /// Threads to analyse with (default: every core). The report is the same, bit for
        /// bit, whatever the number.
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
        jobs: Option<u16>,
        /// Only the sessions at positions i, i + n, i + 2n, … of the sorted list: one task of
        /// a cluster's array job (`--shard $SLURM_ARRAY_TASK_ID/16`); `impactcam fit` is the
        /// reduce.
        #[arg(long, value_name = "i/n")]
        shard: Option<impactcam::batch::Shard>,
    },
    /// The lab daemon: HTTP API and web page to run and watch experiments.
    Serve {
        /// Config file (TOML); without it, the embedded default (the simulated lab).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Address to listen on; off loopback a token (daemon.token or IMPACTCAM_TOKEN) is required.
        #[arg(long)]
        listen: Option<String>,
    },
    /// A series of experiments over tube angles (resumable), then the campaign fit.
    Sweep {
        /// Config file (TOML); without it, the embedded default (the simulated lab).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Tube angles, a:b:step in degrees (inclusive), e.g. 10:65:5.
        #[arg(long)]
        tube_angles: String,
        /// Simulator only: impact offsets a:b:step (the simulated tubes meet with a horizontal
        /// relative velocity, so obliquity is set by the offset, not the tube angle).
        #[arg(long)]
        impact_offsets: Option<String>,
        /// Experiments at each point of the sweep.
        #[arg(long, default_value_t = 1)]
        repeats: u32,
        /// Campaign directory; an existing one is resumed.
        #[arg(long)]
        dir: Option<PathBuf>,
    },
    /// Fit e, mu, beta0 and the break point over many collisions.
    Fit {
        /// report.json files, session directories or campaign directories.
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        /// Print the fit as JSON on stdout instead of the table.
        #[arg(long)]
        json: bool,
        /// Also write fit.json, collisions.csv, psi.svg and report.html here.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Export a session's frames: a multi-page TIFF with ImageJ's frame interval (Fiji opens
    /// it), Photron MRAW + CIH, or FMF.
    Export {
        /// The session directory whose frames are exported.
        session: PathBuf,
        /// The file to write (replaced whole, never left half-written); for mraw, OUT.mraw and
        /// OUT.cih.
        out: Option<PathBuf>,
        /// tiff, mraw or fmf.
        #[arg(long, value_enum)]
        format: Option<ExportFormatArg>,
        /// The same as `--format tiff OUT` (kept for existing scripts).
        #[arg(long, conflicts_with_all = ["out", "format"])]
        tiff: Option<PathBuf>,
    },
    /// Make a session of another camera's file (Photron .cih/.cihx + .mraw, Phantom .cine,
    /// FMF, a TIFF stack, or numbered PNG/TIFF/BMP images), so that replay, the page and
    /// campaigns use it like a recording.
    Import {
        /// The footage: a file, a directory of numbered images, or a pattern like frame_%05d.png.
        file: PathBuf,
        /// The new session directory.
        #[arg(long)]
        out: PathBuf,
        /// The rig's config (geometry, spheres); the file's own frame size and rate are used.
        /// Needed for footage that states no frame rate (images, TIFF, FMF without times).
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// What this machine offers: cameras (by built-in backend) and serial ports.
    Devices,
    /// Configuration: check a file, or print the embedded default.
    Config {
        #[command(subcommand)]
        action: ConfigAction,
    },
    /// Benchmarks, printed as ratios against a baseline measured in the same run.
    Bench {
        #[command(subcommand)]
        what: BenchWhat,
    },
}

#[derive(Subcommand)]
pub(crate) enum ConfigAction {
    /// Validate a config file without touching hardware.
    Check {
        /// The config file (TOML) to check.
        file: PathBuf,
    },
    /// Print the embedded default config.
    Default,
}

#[derive(Subcommand)]
pub(crate) enum BenchWhat {
    /// Recorder throughput into RAM and onto disk against a raw sequential write.
    Capture {
        /// Frames per measurement (fewer, and the session's few closing fsyncs weigh in a
        /// round that lasts a tenth of a second).
        #[arg(long, default_value_t = 6000)]
        frames: usize,
        /// Where the disk measurements write (a temporary directory inside it).
        #[arg(long, default_value = ".")]
        dir: PathBuf,
    },
    /// N experiments back to back through the daemon; memory and file descriptors compared.
    Soak {
        /// Experiments to run back to back.
        #[arg(long, default_value_t = 100)]
        experiments: usize,
        /// Where the daemon writes its sessions (a temporary directory inside it).
        #[arg(long, default_value = ".")]
        dir: PathBuf,
    },
    /// Relay pulse latency and jitter over a serial line, against emulated modules.
    Relay {
        /// Pulses per emulated module.
        #[arg(long, default_value_t = 50)]
        pulses: usize,
        /// Length of each pulse, ms.
        #[arg(long, default_value_t = 20.0)]
        pulse_ms: f64,
    },
    /// The analysis on recordings from an independent renderer (folders with frames.tif,
    /// calibration.json, centres.csv, truth.json), against their ground truth.
    Validation {
        /// The folder holding the recordings, e.g. the lab's shared validation set.
        dir: PathBuf,
        /// Change each recording's frames first, as a camera and its software may save them:
        /// `gamma:G` (an encoding curve), `12-bit` (12-bit levels in a 16-bit file), `stuck:N`
        /// (N hot and dead pixels), `smoothed-noise:S` (noise of σ S grey levels correlated
        /// between neighbours). Repeat to combine, in order.
        #[arg(long = "saved-as", value_name = "HOW")]
        saved_as: Vec<impactcam::bench::saved_as::SavedAs>,
    },
    /// The analysis on non-ideal rigs drawn at random (roll, mirror tilt, the direct camera's
    /// pitch and yaw, perspective, lens; varied looks), each analysed with its exact map, with
    /// the maps calibrate finds, and with the shorthand (which must warn).
    Rigs {
        /// How many rigs.
        #[arg(long, default_value_t = 12)]
        experiments: usize,
        /// Where sessions are recorded while they are analysed (removed afterwards).
        #[arg(long, default_value = ".")]
        dir: PathBuf,
    },
    /// The analysis's CPU time per frame on one thread, whole and by stage, against reading
    /// the frames and a threshold + moments centroid on the same frames.
    Analysis {
        /// How many hw-sim sessions (varied looks) to time.
        #[arg(long, default_value_t = 6)]
        experiments: usize,
        /// Also time an independent renderer's recordings (a folder like the one `bench
        /// validation` reads).
        #[arg(long)]
        validation: Option<PathBuf>,
        /// Also time OpenCV's HoughCircles on the same frames, with this Python (one that has
        /// `cv2`, e.g. a venv with opencv-python-headless).
        #[arg(long, value_name = "PYTHON")]
        opencv: Option<PathBuf>,
        /// Where sessions are recorded while they are timed (removed afterwards).
        #[arg(long, default_value = ".")]
        dir: PathBuf,
    },
    /// Accuracy of impactcam's methods and the thesis's against simulated ground truth.
    Accuracy {
        /// A small sweep (4 experiments) instead of the full one.
        #[arg(long)]
        quick: bool,
        /// Run the sweep this many times, each with other seeds, and pool the figures.
        #[arg(long, default_value_t = 1)]
        repeat: u32,
        /// How the rig looks: `default` (hw-sim's own look, on which the analysis was
        /// developed: an in-distribution figure), `varied` (each experiment draws a look family
        /// and its parameters from its seed), or one family: side_lit, specular, backlit,
        /// cluttered, defocus, paint, mixed; or `overexposed` (side-lit, every sphere's lit side at
        /// the camera's ceiling) or `grey_ground` (side-lit over a grey ground, every sphere's
        /// shaded limb darker than it), which `varied` does not draw.
        #[arg(long, default_value = "default")]
        looks: String,
        /// The camera's exposure, ms: hw-sim smears the spheres over it, and the config tells
        /// the analysis (`camera.exposure_us`). Without it, hw-sim's 0.1 ms, not stated.
        #[arg(long)]
        exposure_ms: Option<f64>,
        /// The lamps flicker by this much, per cent of their mean light, at 100 Hz (a lamp on
        /// 50 Hz mains; `sim.flicker_percent`); needs `--looks` other than `default`. The
        /// analysis is not told.
        #[arg(long)]
        flicker_percent: Option<f64>,
        /// Where sessions are recorded while they are analysed (removed afterwards, unless
        /// `--keep`).
        #[arg(long, default_value = ".")]
        dir: PathBuf,
        /// Keep the recorded sessions in `--dir`, so that another build can be measured on
        /// the same frames with `--sessions`.
        #[arg(long)]
        keep: bool,
        /// Record nothing: analyse these sessions, recorded before with `--keep` (or
        /// directories of them), each with its own config and `truth.json`. Two builds then
        /// differ only by what they do, not by which experiments hw-sim filmed.
        #[arg(long, num_args = 1.., conflicts_with_all = ["quick", "repeat", "looks", "exposure_ms", "flicker_percent", "keep"])]
        sessions: Vec<PathBuf>,
    },
}

/// `export --format`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormatArg {
    Tiff,
    Mraw,
    Fmf,
}
