//! How a camera and its software may save the frames a recording was rendered as, for `bench
//! validation --saved-as`: a gamma curve, 12-bit levels in a 16-bit file, stuck pixels, noise
//! correlated between neighbouring pixels. None of them is in hw-sim's default look or in the
//! independent renders; each is a way a lab's footage differs from both (docs/accuracy.md,
//! session 49). The frames are read from a TIFF stack, changed, and written to another.

use std::path::Path;
use std::str::FromStr;
use tiff::encoder::{colortype, TiffEncoder};

/// One change to the frames, in the order given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SavedAs {
    /// `gamma:G`: each level l becomes 255·(l/255)^(1/G), as a camera's encoding curve (2.2 for
    /// sRGB-like).
    Gamma(f64),
    /// `12-bit`: levels ×16 with a uniform dither of one 12-bit code, in a 16-bit file whose
    /// pixels stay below 4096, as a 12-bit camera's frames exported as they are.
    TwelveBit,
    /// `stuck:N`: N distinct pixels at places drawn from a fixed seed, half at the top of the
    /// range and half at 0 in every frame, as a sensor's hot and dead pixels.
    Stuck(u32),
    /// `smoothed-noise:S`: noise of σ S grey levels added, smoothed by a 3 × 3 binomial kernel
    /// and brought back to σ S, as a demosaiced or resampled image's.
    SmoothedNoise(f64),
}

impl FromStr for SavedAs {
    type Err = String;
    fn from_str(s: &str) -> Result<SavedAs, String> {
        let expected = "expected gamma:G (0.2–5), 12-bit, stuck:N (1–10000) or smoothed-noise:S (0–50 grey levels)";
        let (name, value) = s.split_once(':').unwrap_or((s, ""));
        let number = || -> Result<f64, String> {
            value
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{s:?}: {value:?} is not a number; {expected}"))
        };
        let how = match name {
            "gamma" => SavedAs::Gamma(number()?),
            "12-bit" if value.is_empty() => SavedAs::TwelveBit,
            "stuck" => SavedAs::Stuck(number()? as u32),
            "smoothed-noise" => SavedAs::SmoothedNoise(number()?),
            _ => return Err(format!("{s:?}: {expected}")),
        };
        let fits = match how {
            SavedAs::Gamma(g) => (0.2..=5.0).contains(&g),
            SavedAs::TwelveBit => true,
            SavedAs::Stuck(n) => (1..=10_000).contains(&n),
            SavedAs::SmoothedNoise(sigma) => (0.0..=50.0).contains(&sigma),
        };
        if fits {
            Ok(how)
        } else {
            Err(format!("{s:?}: out of range; {expected}"))
        }
    }
}

/// The seed of the changes' random draws (stuck places, dither, noise): fixed, so that two
/// builds see the same frames.
const SEED: u64 = 0x5A7E_D0A5;

/// Writes `frames` (a TIFF stack of 8-bit frames) changed by `how` to `out`.
pub fn write_changed(frames: &Path, how: &[SavedAs], out: &Path) -> Result<(), String> {
    let mut file = crate::footage::open(frames, Some(1000.0)).map_err(|e| e.to_string())?;
    let info = file.info().clone();
    if info.bytes_per_pixel != 1 {
        return Err(format!(
            "{}: {}-byte pixels, expected an 8-bit stack to change",
            frames.display(),
            info.bytes_per_pixel
        ));
    }
    let (w, h) = (info.width as usize, info.height as usize);
    let npx = w * h;
    let mut rng = hw_sim::Rng::new(SEED);
    let wanted: usize = how
        .iter()
        .map(|s| match s {
            SavedAs::Stuck(n) => *n as usize,
            _ => 0,
        })
        .sum();
    let stuck = hw_sim::render::stuck_places(SEED, wanted, npx);
    let wide = how.contains(&SavedAs::TwelveBit);
    let top = if wide { 4095.0 } else { 255.0 };
    let io = |e: std::io::Error| format!("{}: {e}", out.display());
    let mut writer = std::io::BufWriter::new(std::fs::File::create(out).map_err(io)?);
    let mut enc = TiffEncoder::new(&mut writer).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut raw = Vec::new();
    for i in 0..file.len() {
        file.read(i, &mut raw).map_err(|e| e.to_string())?;
        let mut px: Vec<f64> = raw.iter().map(|&b| f64::from(b)).collect();
        for s in how {
            match *s {
                SavedAs::Gamma(g) => {
                    for p in &mut px {
                        *p = 255.0 * (p.max(0.0) / 255.0).powf(1.0 / g);
                    }
                }
                SavedAs::TwelveBit => {
                    for p in &mut px {
                        *p = *p * 16.0 + 16.0 * rng.uniform();
                    }
                }
                SavedAs::SmoothedNoise(sigma) => add_smoothed_noise(&mut px, w, h, sigma, &mut rng),
                SavedAs::Stuck(_) => {}
            }
        }
        for &(k, hot) in &stuck {
            px[k] = if hot { top } else { 0.0 };
        }
        let r = if wide {
            let data: Vec<u16> = px
                .iter()
                .map(|p| p.round().clamp(0.0, top) as u16)
                .collect();
            enc.write_image::<colortype::Gray16>(info.width, info.height, &data)
        } else {
            let data: Vec<u8> = px.iter().map(|p| p.round().clamp(0.0, top) as u8).collect();
            enc.write_image::<colortype::Gray8>(info.width, info.height, &data)
        };
        r.map_err(|e| format!("{}: frame {i}: {e}", out.display()))?;
    }
    std::io::Write::flush(&mut writer).map_err(io)
}

/// Adds noise of σ `sigma`, smoothed by the 3 × 3 binomial kernel [1 2 1]ᵀ[1 2 1]/16 (edges
/// clamped) and scaled back to σ `sigma` (the kernel leaves (3/8)² of the variance).
fn add_smoothed_noise(px: &mut [f64], w: usize, h: usize, sigma: f64, rng: &mut hw_sim::Rng) {
    let white: Vec<f64> = (0..w * h).map(|_| rng.gaussian()).collect();
    let at = |u: isize, v: isize| {
        let (u, v) = (u.clamp(0, w as isize - 1), v.clamp(0, h as isize - 1));
        white[v as usize * w + u as usize]
    };
    let weight = [1.0, 2.0, 1.0];
    for v in 0..h {
        for u in 0..w {
            let mut sum = 0.0;
            for (dv, wv) in weight.iter().enumerate() {
                for (du, wu) in weight.iter().enumerate() {
                    sum += wv * wu * at(u as isize + du as isize - 1, v as isize + dv as isize - 1);
                }
            }
            px[v * w + u] += sigma * sum / 16.0 / 0.375;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_change_is_named_and_checked() {
        assert_eq!("gamma:2.2".parse(), Ok(SavedAs::Gamma(2.2)));
        assert_eq!("12-bit".parse(), Ok(SavedAs::TwelveBit));
        assert_eq!("stuck:200".parse(), Ok(SavedAs::Stuck(200)));
        assert_eq!("smoothed-noise:2".parse(), Ok(SavedAs::SmoothedNoise(2.0)));
        for bad in ["gamma:9", "gamma:x", "stuck:0", "jpeg:70", "12-bit:3"] {
            let e = bad.parse::<SavedAs>().unwrap_err();
            assert!(e.contains(bad) && e.contains("expected"), "{e}");
        }
    }

    /// The changed stack reads back as such: 12-bit levels (which the reader scales to 16 bits
    /// and says so), stuck pixels at both ends, a gamma that brightens the mid-tones, and
    /// smoothed noise whose neighbours correlate.
    #[test]
    fn a_changed_stack_reads_back_changed() {
        let d = tempfile::tempdir().unwrap();
        let (w, h) = (32u32, 24u32);
        let src = d.path().join("in.tif");
        {
            let mut enc = TiffEncoder::new(std::fs::File::create(&src).unwrap()).unwrap();
            for _ in 0..3 {
                enc.write_image::<colortype::Gray8>(w, h, &vec![64u8; (w * h) as usize])
                    .unwrap();
            }
        }
        let read = |how: &[SavedAs]| {
            let out = d.path().join("out.tif");
            write_changed(&src, how, &out).unwrap();
            let mut f = crate::footage::open(&out, Some(1000.0)).unwrap();
            let mut raw = Vec::new();
            f.read(1, &mut raw).unwrap();
            (f.info().clone(), raw)
        };
        let (info, raw) = read(&[SavedAs::TwelveBit]);
        assert_eq!(info.bytes_per_pixel, 2);
        assert!(info.notes.iter().any(|n| n.contains("taken as 12-bit")));
        let first = u16::from_le_bytes([raw[0], raw[1]]);
        assert!((64 * 256..65 * 256).contains(&first), "{first}");
        let (_, raw) = read(&[SavedAs::Stuck(40)]);
        assert!(raw.contains(&255) && raw.contains(&0));
        assert_eq!(raw.iter().filter(|&&b| b == 64).count(), raw.len() - 40);
        let (_, raw) = read(&[SavedAs::Gamma(2.2)]);
        assert_eq!(
            raw[0],
            (255.0 * (64.0f64 / 255.0).powf(1.0 / 2.2)).round() as u8
        );
        let (_, raw) = read(&[SavedAs::SmoothedNoise(4.0)]);
        let dev: Vec<f64> = raw.iter().map(|&b| f64::from(b) - 64.0).collect();
        let var = dev.iter().map(|x| x * x).sum::<f64>() / dev.len() as f64;
        let lag: f64 = (0..dev.len() - 1)
            .filter(|k| (k + 1) % w as usize != 0)
            .map(|k| dev[k] * dev[k + 1])
            .sum::<f64>()
            / dev.len() as f64;
        assert!((var.sqrt() - 4.0).abs() < 1.0, "σ {}", var.sqrt());
        assert!(lag / var > 0.4, "neighbours' correlation {}", lag / var);
    }
}
