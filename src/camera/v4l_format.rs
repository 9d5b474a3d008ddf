//! The V4L2 backend's pure parts, tested here without a device: which of the formats a camera
//! offers to ask for, and how its frames become the recorder's grey frames (GREY and Y16 are
//! copied row by row past any line padding; YUYV keeps its luma bytes).

use crate::config::PixelFormat;

/// The V4L2 pixel formats impactcam can use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fourcc {
    Grey,
    Y16,
    Yuyv,
}

impl Fourcc {
    pub fn code(self) -> [u8; 4] {
        match self {
            Fourcc::Grey => *b"GREY",
            Fourcc::Y16 => *b"Y16 ",
            Fourcc::Yuyv => *b"YUYV",
        }
    }
    pub fn from_code(code: &[u8; 4]) -> Option<Fourcc> {
        match code {
            b"GREY" => Some(Fourcc::Grey),
            b"Y16 " => Some(Fourcc::Y16),
            b"YUYV" => Some(Fourcc::Yuyv),
            _ => None,
        }
    }
}

/// The best offered format for the wanted pixel format: native grey of the same depth first,
/// then the other grey depth, then YUYV's luma.
pub fn choose(offered: &[[u8; 4]], wanted: PixelFormat) -> Option<Fourcc> {
    let order: &[Fourcc] = match wanted {
        PixelFormat::Mono8 => &[Fourcc::Grey, Fourcc::Y16, Fourcc::Yuyv],
        PixelFormat::Mono16 => &[Fourcc::Y16, Fourcc::Grey, Fourcc::Yuyv],
    };
    order.iter().copied().find(|f| offered.contains(&f.code()))
}

/// Converts one V4L2 frame (`stride` bytes per line) to a row-major grey frame of the wanted
/// format (16-bit little-endian; 8-bit sources scaled by 256, 16-bit sources to 8 by the high
/// byte). None if the buffer is too short for the size.
pub fn to_grey(
    src: &[u8],
    from: Fourcc,
    width: usize,
    height: usize,
    stride: usize,
    wanted: PixelFormat,
    out: &mut Vec<u8>,
) -> Option<()> {
    let in_bpp = match from {
        Fourcc::Grey => 1,
        Fourcc::Y16 | Fourcc::Yuyv => 2,
    };
    if stride < width * in_bpp || src.len() < stride * (height - 1) + width * in_bpp {
        return None;
    }
    out.clear();
    for row in 0..height {
        let line = &src[row * stride..row * stride + width * in_bpp];
        for x in 0..width {
            // Sample as 16-bit.
            let v16: u16 = match from {
                Fourcc::Grey => (line[x] as u16) << 8,
                Fourcc::Y16 => u16::from_le_bytes([line[2 * x], line[2 * x + 1]]),
                Fourcc::Yuyv => (line[2 * x] as u16) << 8,
            };
            match wanted {
                PixelFormat::Mono8 => out.push((v16 >> 8) as u8),
                PixelFormat::Mono16 => out.extend_from_slice(&v16.to_le_bytes()),
            }
        }
    }
    Some(())
}

/// V4L2 sequence numbers are 32-bit: continue them past the wrap.
pub fn extend_sequence(last: Option<u64>, seq: u32) -> u64 {
    match last {
        Some(prev) => {
            let base = prev & !0xFFFF_FFFF;
            let candidate = base | seq as u64;
            if candidate < prev {
                candidate + (1 << 32)
            } else {
                candidate
            }
        }
        None => seq as u64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_choice_prefers_native_grey_of_the_same_depth() {
        assert_eq!(
            choose(&[*b"YUYV", *b"GREY"], PixelFormat::Mono8),
            Some(Fourcc::Grey)
        );
        assert_eq!(
            choose(&[*b"YUYV", *b"GREY", *b"Y16 "], PixelFormat::Mono16),
            Some(Fourcc::Y16)
        );
        assert_eq!(choose(&[*b"YUYV"], PixelFormat::Mono8), Some(Fourcc::Yuyv));
        assert_eq!(choose(&[*b"MJPG"], PixelFormat::Mono8), None);
    }

    #[test]
    fn conversions_skip_padding_and_keep_luma() {
        // 2×2 GREY with 4-byte stride.
        let grey = [10, 20, 0, 0, 30, 40, 0, 0];
        let mut out = Vec::new();
        to_grey(&grey, Fourcc::Grey, 2, 2, 4, PixelFormat::Mono8, &mut out).unwrap();
        assert_eq!(out, vec![10, 20, 30, 40]);
        to_grey(&grey, Fourcc::Grey, 2, 2, 4, PixelFormat::Mono16, &mut out).unwrap();
        assert_eq!(out, vec![0, 10, 0, 20, 0, 30, 0, 40]);
        // YUYV: Y0 U Y1 V.
        let yuyv = [100, 128, 110, 128, 120, 128, 130, 128];
        to_grey(&yuyv, Fourcc::Yuyv, 2, 2, 4, PixelFormat::Mono8, &mut out).unwrap();
        assert_eq!(out, vec![100, 110, 120, 130]);
        let y16 = 0x1234u16.to_le_bytes();
        to_grey(
            &[y16[0], y16[1]],
            Fourcc::Y16,
            1,
            1,
            2,
            PixelFormat::Mono8,
            &mut out,
        )
        .unwrap();
        assert_eq!(out, vec![0x12]);
        assert!(to_grey(
            &[1, 2, 3],
            Fourcc::Grey,
            2,
            2,
            2,
            PixelFormat::Mono8,
            &mut out
        )
        .is_none());
    }

    #[test]
    fn sequence_numbers_continue_past_the_32_bit_wrap_and_gaps_show() {
        let s = [u32::MAX - 1, u32::MAX, 0, 2];
        let mut last = None;
        let ext: Vec<u64> = s
            .iter()
            .map(|&q| {
                let e = extend_sequence(last, q);
                last = Some(e);
                e
            })
            .collect();
        assert_eq!(
            ext,
            vec![u32::MAX as u64 - 1, u32::MAX as u64, 1 << 32, (1 << 32) + 2]
        );
        let metas: Vec<crate::session::FrameMeta> = ext
            .iter()
            .map(|&frame_id| crate::session::FrameMeta {
                frame_id,
                timestamp_ns: 0,
            })
            .collect();
        assert_eq!(crate::session::count_gaps(&metas), 1);
    }
}
