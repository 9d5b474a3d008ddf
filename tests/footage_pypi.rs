//! impactcam's camera files against independent code from PyPI (`tests/footage_pypi.py`):
//! pyMRAW's MRAW/CIH and motmot's FMF are read by impactcam with the same pixels and times, and
//! impactcam's MRAW, FMF and TIFF exports and its cines are read by pyMRAW, motmot, tifffile,
//! pycine and AMETEK's cinereader with the same pixels, times and ImageJ metadata.
//!
//! The Python packages come from PyPI: `scripts/test` installs them into a virtual environment
//! and names its interpreter in `IMPACTCAM_FOOTAGE_PYTHON`.

mod common;

use impactcam::footage::cine::{self, CineSpec};
use impactcam::footage::FrameFile;
use impactcam::session::SessionReader;
use std::path::Path;
use std::process::Command;

fn python() -> String {
    std::env::var("IMPACTCAM_FOOTAGE_PYTHON").unwrap_or_else(|_| {
        panic!("IMPACTCAM_FOOTAGE_PYTHON is not set: run scripts/test, which installs pyMRAW, pycine, cinereader, motmot.FlyMovieFormat and tifffile into a virtual environment")
    })
}

fn script(py: &str, what: &str, dir: &Path) -> String {
    let out = Command::new(py)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/footage_pypi.py"))
        .arg(what)
        .arg(dir)
        .output()
        .expect("the Python interpreter runs");
    assert!(
        out.status.success(),
        "footage_pypi.py {what}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn read_all(f: &mut dyn FrameFile) -> Vec<u8> {
    let mut all = Vec::new();
    let mut buf = Vec::new();
    for k in 0..f.len() {
        f.read(k, &mut buf).unwrap();
        all.extend_from_slice(&buf);
    }
    all
}

#[test]
#[ignore = "needs Python packages from PyPI: scripts/test installs them and runs this test"]
fn files_from_pypi_writers_are_read_and_pypi_readers_read_ours() {
    let py = python();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();

    // Theirs, read by impactcam.
    eprint!("{}", script(&py, "write", dir));
    let mut m8 = impactcam::footage::open(&dir.join("py8.cih"), None).unwrap();
    assert_eq!((m8.info().width, m8.info().height, m8.len()), (40, 24, 5));
    assert_eq!(m8.info().frame_rate_hz, Some(2000.0));
    assert_eq!(
        read_all(m8.as_mut()),
        std::fs::read(dir.join("py8.raw")).unwrap()
    );
    let mut m16 = impactcam::footage::open(&dir.join("py16.mraw"), None).unwrap();
    // pyMRAW writes 16-bit files with 12 significant bits (low side): read scaled ×16.
    let want16: Vec<u8> = std::fs::read(dir.join("py16.raw"))
        .unwrap()
        .chunks_exact(2)
        .flat_map(|c| (u16::from_le_bytes([c[0], c[1]]) << 4).to_le_bytes())
        .collect();
    assert_eq!(read_all(m16.as_mut()), want16);
    let mut f = impactcam::footage::open(&dir.join("py.fmf"), None).unwrap();
    assert_eq!(
        read_all(f.as_mut()),
        std::fs::read(dir.join("py8.raw")).unwrap()
    );
    let times: Vec<f64> = std::fs::read_to_string(dir.join("py_fmf_times.txt"))
        .unwrap()
        .lines()
        .map(|l| l.parse().unwrap())
        .collect();
    for (k, t) in times.iter().enumerate() {
        let want = ((t - times[0]) * 1e9).round() as u64;
        assert_eq!(f.meta(k).timestamp_ns, want, "FMF frame {k}'s time");
    }

    // Ours, read by them: a recorded session's exports, and cines of its frames.
    let out = common::impactcam(dir, &["run"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let session = common::first_session(dir);
    let s = session.to_str().unwrap();
    for (format, out) in [("tiff", "ours.tif"), ("mraw", "ours"), ("fmf", "ours.fmf")] {
        let o = common::impactcam(dir, &["export", s, "--format", format, out]);
        assert!(o.status.success(), "{format}: {}", common::stderr(&o));
    }
    let mut r = SessionReader::open(&session).unwrap();
    let t0 = r.frames[0].timestamp_ns;
    let mut raw = Vec::new();
    let mut frames = Vec::new();
    let mut buf = Vec::new();
    for i in 0..r.frames.len() {
        r.read_frame(i, &mut buf).unwrap();
        raw.extend_from_slice(&buf);
        frames.push((r.frames[i].timestamp_ns - t0, buf.clone()));
    }
    std::fs::write(dir.join("session.raw"), &raw).unwrap();
    // 20 s into a minute: cinereader counts seconds within the minute.
    let base_ns = 1_700_000_000u64 * 1_000_000_000;
    let fired = r.manifest.trigger.fired_in_frame.unwrap() as usize;
    let spec = CineSpec {
        width: r.width,
        height: r.height,
        bytes_per_pixel: 1,
        real_bpp: 8,
        frame_rate_hz: 1000,
        shutter_ns: 500_000,
        first_image_no: -(fired as i32),
        trigger: cine::time64(base_ns + frames[fired].0),
    };
    let cine_frames: Vec<_> = frames
        .iter()
        .map(|(t, px)| (cine::time64(base_ns + t), px.clone()))
        .collect();
    cine::write(&dir.join("ours8.cine"), &spec, &cine_frames).unwrap();
    let from_trigger: Vec<f64> = frames
        .iter()
        .map(|(t, _)| (*t as f64 - frames[fired].0 as f64) * 1e-9)
        .collect();
    // 12 significant bits in 16: a ramp over the whole range, three images.
    let (w, h) = (r.width as usize, r.height as usize);
    let ramp: Vec<Vec<u8>> = (0..3)
        .map(|k| {
            (0..w * h)
                .flat_map(|i| (((i * 7 + k * 1000) % 4096) as u16).to_le_bytes())
                .collect()
        })
        .collect();
    std::fs::write(dir.join("ours16.raw"), ramp.concat()).unwrap();
    let spec16 = CineSpec {
        bytes_per_pixel: 2,
        real_bpp: 12,
        first_image_no: 0,
        ..spec
    };
    let ramp_frames: Vec<_> = ramp
        .iter()
        .enumerate()
        .map(|(k, px)| (cine::time64(base_ns + k as u64 * 1_000_000), px.clone()))
        .collect();
    cine::write(&dir.join("ours16.cine"), &spec16, &ramp_frames).unwrap();
    let meta = serde_json::json!({
        "width": r.width,
        "height": r.height,
        "frames": r.frames.len(),
        "frame_rate_hz": r.manifest.camera.frame_rate_hz,
        "times_s": frames.iter().map(|(t, _)| *t as f64 * 1e-9).collect::<Vec<_>>(),
        "cine_from_trigger_s": from_trigger,
    });
    std::fs::write(dir.join("meta.json"), meta.to_string()).unwrap();
    let said = script(&py, "check", dir);
    eprint!("{said}");
    assert_eq!(said.lines().count(), 5, "every check ran: {said}");
}
