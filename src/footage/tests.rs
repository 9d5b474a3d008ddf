//! Each reader against its writer (or bytes laid out by hand from the format's description):
//! pixels, times, rates and trigger frames come back as written; detection is by content.

use super::*;
use tempfile::tempdir;

fn all_frames(f: &mut dyn FrameFile) -> Vec<Vec<u8>> {
    (0..f.len())
        .map(|k| {
            let mut b = Vec::new();
            f.read(k, &mut b).unwrap();
            b
        })
        .collect()
}

#[test]
fn mraw_8_12_and_16_bit_read_back_with_rate_and_trigger() {
    let d = tempdir().unwrap();
    let f8: Vec<Vec<u8>> = vec![(0..8).collect(), (8..16).collect(), (16..24).collect()];
    photron::write(&d.path().join("a"), 4, 2, 8, 2000.0, -1, &f8).unwrap();
    for name in ["a.cih", "a.mraw"] {
        let mut m = open(&d.path().join(name), None).unwrap();
        assert_eq!(m.info().kind, "mraw");
        assert_eq!(
            (m.info().width, m.info().height, m.info().bytes_per_pixel),
            (4, 2, 1)
        );
        assert_eq!(m.info().frame_rate_hz, Some(2000.0));
        assert_eq!(
            m.info().trigger_frame,
            Some(1),
            "start frame -1: frame 1 is the trigger"
        );
        assert_eq!(m.meta(2).timestamp_ns, 1_000_000);
        assert_eq!(all_frames(m.as_mut()), f8);
    }
    // 12-bit packed: two pixels in three bytes, the first pixel's high byte first.
    let packed = vec![vec![
        0x12, 0x34, 0x56, 0xab, 0xcd, 0xef, 0, 0, 1, 0xff, 0xf0, 0,
    ]];
    photron::write(&d.path().join("b"), 4, 2, 12, 1000.0, 0, &packed).unwrap();
    let mut m = open(&d.path().join("b.cih"), None).unwrap();
    let px: Vec<u16> = all_frames(m.as_mut())[0]
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    let want: Vec<u16> = [0x123, 0x456, 0xabc, 0xdef, 0x000, 0x001, 0xfff, 0x000]
        .iter()
        .map(|v| v << 4)
        .collect();
    assert_eq!(px, want);
    assert!(m.info().notes[0].contains("12-bit pixels scaled ×16"));
    // 16-bit little-endian.
    let f16 = vec![(0..16u8).collect::<Vec<u8>>()];
    photron::write(&d.path().join("c"), 4, 2, 16, 1000.0, 0, &f16).unwrap();
    let mut m = open(&d.path().join("c.mraw"), None).unwrap();
    assert_eq!(m.info().bytes_per_pixel, 2);
    assert_eq!(all_frames(m.as_mut()), f16);
}

#[test]
fn cihx_xml_headers_are_read() {
    let d = tempdir().unwrap();
    let xml = "\u{1}\u{2}binary preamble<?xml version=\"1.0\"?>\n<cih>\n<recordInfo><recordRate>5000</recordRate><shutterSpeed>0.0001</shutterSpeed></recordInfo>\n<frameInfo><totalFrame>2</totalFrame><startFrame>-1</startFrame></frameInfo>\n<imageDataInfo><resolution><width>4</width><height>2</height></resolution><colorInfo><type>Mono</type><bit>8</bit></colorInfo><effectiveBit><depth>8</depth><side>Lower</side></effectiveBit></imageDataInfo>\n<imageFileInfo><fileFormat>MRaw</fileFormat></imageFileInfo>\n</cih>\n";
    std::fs::write(d.path().join("x.cihx"), xml).unwrap();
    std::fs::write(d.path().join("x.mraw"), [5u8; 16]).unwrap();
    let mut m = open(&d.path().join("x.cihx"), None).unwrap();
    assert_eq!(m.info().frame_rate_hz, Some(5000.0));
    assert_eq!(m.info().exposure_s, Some(0.0001));
    assert_eq!(m.info().trigger_frame, Some(1));
    assert_eq!(all_frames(m.as_mut()), vec![vec![5u8; 8]; 2]);
}

#[test]
fn cine_8_and_16_bit_read_back_top_row_first_with_times() {
    let d = tempdir().unwrap();
    let base = 1_700_000_000u64 * 1_000_000_000 + 123_456_789;
    let times = [0u64, 1_000_000, 2_000_000, 3_000_017];
    for (bpp, real) in [(1usize, 8u32), (2, 12)] {
        let frames: Vec<((u32, u32), Vec<u8>)> = times
            .iter()
            .enumerate()
            .map(|(k, t)| {
                let px: Vec<u8> = if bpp == 1 {
                    (0..12).map(|i| (i * 10 + k) as u8).collect()
                } else {
                    (0..12u16)
                        .flat_map(|i| (i * 300 + k as u16).to_le_bytes())
                        .collect()
                };
                (cine::time64(base + t), px)
            })
            .collect();
        let spec = cine::CineSpec {
            width: 4,
            height: 3,
            bytes_per_pixel: bpp,
            real_bpp: real,
            frame_rate_hz: 1000,
            shutter_ns: 250_000,
            first_image_no: -2,
            trigger: cine::time64(base + 2_000_000),
        };
        let p = d.path().join(format!("c{bpp}.cine"));
        cine::write(&p, &spec, &frames).unwrap();
        let mut c = open(&p, None).unwrap();
        assert_eq!(c.info().kind, "cine");
        assert_eq!(c.info().timing, Timing::File);
        assert_eq!(c.info().trigger_frame, Some(2));
        assert_eq!(c.info().first_frame_number, Some(-2));
        assert_eq!(c.info().frame_rate_hz, Some(1000.0));
        assert_eq!(c.info().exposure_s, Some(0.00025));
        let got: Vec<u64> = (0..c.len()).map(|k| c.meta(k).timestamp_ns).collect();
        assert_eq!(got, times, "times from the time block, to the ns");
        let read = all_frames(c.as_mut());
        for (k, (_, px)) in frames.iter().enumerate() {
            if bpp == 1 {
                assert_eq!(&read[k], px);
            } else {
                let want: Vec<u8> = px
                    .chunks_exact(2)
                    .flat_map(|c| (u16::from_le_bytes([c[0], c[1]]) << 4).to_le_bytes())
                    .collect();
                assert_eq!(read[k], want, "12 significant bits scaled to 16");
            }
        }
    }
}

#[test]
fn fmf_rows_in_pixels_or_bytes_and_nan_times() {
    let d = tempdir().unwrap();
    // (Levels up to 0xF8F0: a 16-bit camera's, which `LowBits` leaves as they are.)
    let f: Vec<(f64, Vec<u8>)> = vec![
        (10.5, (0..16).map(|b| b * 8).collect()),
        (10.502, (16..32).map(|b| b * 8).collect()),
    ];
    fmf::write(&d.path().join("a.fmf"), 4, 2, 2, &f).unwrap();
    let mut m = open(&d.path().join("a.fmf"), None).unwrap();
    assert_eq!((m.info().width, m.info().bytes_per_pixel), (4, 2));
    assert_eq!(m.meta(1).timestamp_ns, 2_000_000);
    assert_eq!(all_frames(m.as_mut()), vec![f[0].1.clone(), f[1].1.clone()]);
    // The same file with its row width in bytes (8) and the frame count left at 0.
    let mut bytes = std::fs::read(d.path().join("a.fmf")).unwrap();
    let at = 4 + 4 + 6 + 4;
    bytes[at + 4..at + 8].copy_from_slice(&8u32.to_le_bytes());
    bytes[at + 16..at + 24].copy_from_slice(&0u64.to_le_bytes());
    std::fs::write(d.path().join("b.fmf"), &bytes).unwrap();
    let m = open(&d.path().join("b.fmf"), None).unwrap();
    assert_eq!((m.info().width, m.len()), (4, 2));
    // NaN times: the rate must be given, and is used.
    let nan = vec![(f64::NAN, vec![0u8; 8]), (f64::NAN, vec![1u8; 8])];
    fmf::write(&d.path().join("n.fmf"), 4, 2, 1, &nan).unwrap();
    let e = open(&d.path().join("n.fmf"), None)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("camera.frame_rate_hz"), "{e}");
    let m = open(&d.path().join("n.fmf"), Some(500.0)).unwrap();
    assert_eq!(
        (m.info().timing, m.meta(1).timestamp_ns),
        (Timing::Rate, 2_000_000)
    );
}

fn png8(path: &std::path::Path, px: &[u8]) {
    let f = File::create(path).unwrap();
    let mut enc = png::Encoder::new(f, 4, 2);
    enc.set_color(png::ColorType::Grayscale);
    enc.write_header().unwrap().write_image_data(px).unwrap();
}

/// An 8-bit BMP with a grey palette, rows bottom first, each padded to 4 bytes (width 3).
fn bmp8(path: &std::path::Path, rows_top_first: &[[u8; 3]]) {
    let h = rows_top_first.len() as u32;
    let stride = 4u32;
    let pixels_at = 14 + 40 + 256 * 4;
    let mut b = Vec::new();
    b.extend_from_slice(b"BM");
    b.extend_from_slice(&(pixels_at + stride * h).to_le_bytes());
    b.extend_from_slice(&[0; 4]);
    b.extend_from_slice(&pixels_at.to_le_bytes());
    b.extend_from_slice(&40u32.to_le_bytes());
    b.extend_from_slice(&3i32.to_le_bytes());
    b.extend_from_slice(&(h as i32).to_le_bytes());
    b.extend_from_slice(&1u16.to_le_bytes());
    b.extend_from_slice(&8u16.to_le_bytes());
    b.extend_from_slice(&[0; 24]);
    for g in 0..=255u8 {
        b.extend_from_slice(&[g, g, g, 0]);
    }
    for r in rows_top_first.iter().rev() {
        b.extend_from_slice(r);
        b.push(0);
    }
    std::fs::write(path, b).unwrap();
}

#[test]
fn numbered_images_with_a_gap_are_frames_with_a_drop() {
    let d = tempdir().unwrap();
    for n in [7, 8, 10] {
        png8(&d.path().join(format!("shot_{n:03}.png")), &[n as u8; 8]);
    }
    std::fs::write(d.path().join("notes.txt"), "x").unwrap();
    for path in [
        d.path().to_path_buf(),
        d.path().join("shot_%03d.png"),
        d.path().join("shot_008.png"),
    ] {
        let mut s = open(&path, Some(1000.0)).unwrap();
        assert_eq!(s.info().kind, "sequence");
        assert_eq!(s.len(), 3);
        assert_eq!(s.meta(2).frame_id, 3, "frame 10 is 3 after frame 7");
        assert_eq!(s.meta(2).timestamp_ns, 3_000_000);
        assert_eq!(all_frames(s.as_mut())[2], vec![10u8; 8]);
        assert!(s.info().notes[0].contains("1 frame number(s) missing"));
    }
    assert!(open(&d.path().join("shot_%03d.png"), None)
        .err()
        .unwrap()
        .to_string()
        .contains("camera.frame_rate_hz"));
    let b = tempdir().unwrap();
    bmp8(&b.path().join("f1.bmp"), &[[1, 2, 3], [4, 5, 6]]);
    bmp8(&b.path().join("f2.bmp"), &[[7, 8, 9], [10, 11, 12]]);
    let mut s = open(b.path(), Some(100.0)).unwrap();
    assert_eq!((s.info().width, s.info().height), (3, 2));
    assert_eq!(
        all_frames(s.as_mut()),
        vec![vec![1, 2, 3, 4, 5, 6], vec![7, 8, 9, 10, 11, 12]]
    );
}

#[test]
fn a_tiff_stack_is_read_page_by_page_and_imagej_says_its_rate() {
    use tiff::encoder::{colortype, TiffEncoder};
    let d = tempdir().unwrap();
    let p = d.path().join("s.tif");
    let mut enc = TiffEncoder::new(File::create(&p).unwrap()).unwrap();
    for k in 0..3u8 {
        let mut img = enc.new_image::<colortype::Gray8>(4, 2).unwrap();
        if k == 0 {
            img.encoder()
                .write_tag(
                    tiff::tags::Tag::ImageDescription,
                    "ImageJ=1.11a\nimages=3\nframes=3\nfinterval=0.004\n",
                )
                .unwrap();
        }
        img.write_data(&[k; 8]).unwrap();
    }
    drop(enc);
    let mut s = open(&p, None).unwrap();
    assert_eq!(s.info().kind, "tiff");
    assert_eq!(s.info().frame_rate_hz, Some(250.0));
    assert_eq!(s.meta(2).timestamp_ns, 8_000_000);
    // Out of order: each page is found again.
    let mut b = Vec::new();
    s.read(2, &mut b).unwrap();
    assert_eq!(b, vec![2u8; 8]);
    s.read(0, &mut b).unwrap();
    assert_eq!(b, vec![0u8; 8]);
}

#[test]
fn the_committed_fuzz_seeds_open() {
    // The seeds in fuzz/corpus/footage are valid files of each format, so the fuzzer starts
    // from inputs that reach the frame readers.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/footage");
    for name in ["mraw8", "mraw12", "cine16", "fmf8", "png16"] {
        let data = std::fs::read(dir.join(name)).unwrap();
        let t = tempdir().unwrap();
        let path = match data[0] {
            0 => {
                let i = data[1..].windows(3).position(|w| w == b"\0\0\0").unwrap();
                std::fs::write(t.path().join("in.cih"), &data[1..1 + i]).unwrap();
                std::fs::write(t.path().join("in.mraw"), &data[i + 4..]).unwrap();
                t.path().join("in.cih")
            }
            1 => t.path().join("in.cine"),
            2 => t.path().join("in.fmf"),
            _ => t.path().join("f_0001.png"),
        };
        if data[0] != 0 {
            std::fs::write(&path, &data[1..]).unwrap();
        }
        let mut f = open(&path, Some(1000.0)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(!all_frames(f.as_mut()).is_empty(), "{name}");
    }
}

/// A 16-bit stack of `pages` pages of 4 × 2 pixels, page k holding `level(k)` everywhere.
fn tiff16(path: &Path, pages: u16, level: impl Fn(u16) -> u16) {
    use tiff::encoder::{colortype, TiffEncoder};
    let mut enc = TiffEncoder::new(File::create(path).unwrap()).unwrap();
    for k in 0..pages {
        enc.write_image::<colortype::Gray16>(4, 2, &[level(k); 8])
            .unwrap();
    }
}

#[test]
fn sixteen_bit_footage_that_stays_within_twelve_bits_is_scaled_as_twelve_bit() {
    let d = tempdir().unwrap();
    // A 12-bit camera's frames exported as they are: the brightest page 4000.
    let p = d.path().join("twelve.tif");
    tiff16(&p, 3, |k| [100, 4000, 2048][k as usize]);
    let mut s = open(&p, Some(1000.0)).unwrap();
    let frames = all_frames(s.as_mut());
    let first = u16::from_le_bytes([frames[1][0], frames[1][1]]);
    assert_eq!(first, 4000 * 16, "12 significant bits scaled ×16");
    assert!(
        s.info().notes.iter().any(|n| n.contains("taken as 12-bit")
            && n.contains("the largest is 4000")
            && n.contains("twelve.tif")),
        "{:?}",
        s.info().notes
    );
    // A true 16-bit recording (one page reaches 2¹⁴) is read as it is, with no note.
    let p = d.path().join("sixteen.tif");
    tiff16(&p, 3, |k| [100, 20_000, 2048][k as usize]);
    let mut s = open(&p, Some(1000.0)).unwrap();
    let frames = all_frames(s.as_mut());
    assert_eq!(u16::from_le_bytes([frames[0][0], frames[0][1]]), 100);
    assert!(s.info().notes.is_empty(), "{:?}", s.info().notes);
    // One image (a dot grid's) by its own pixels: 10-bit.
    let p = d.path().join("grid.tif");
    tiff16(&p, 1, |_| 1000);
    let mut buf = Vec::new();
    assert_eq!(read_image(&p, &mut buf).unwrap(), (4, 2, 2));
    assert_eq!(u16::from_le_bytes([buf[0], buf[1]]), 1000 * 64);
}

#[test]
fn a_sample_beyond_the_stated_bits_is_the_top_of_the_range_not_wrapped() {
    let mut buf: Vec<u8> = [4095u16, 4096, 1]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    widen_le16(&mut buf, 12);
    let got: Vec<u16> = buf
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    assert_eq!(got, vec![4095 * 16, u16::MAX, 16]);
}
