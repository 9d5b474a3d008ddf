//! The figures' bitmap font: 7×14 px cells of 4-bit coverage, rendered from DejaVu Sans Mono
//! 12 px. The glyphs are data (`font.txt`), written by `scripts/gen-font.py` from the font
//! file; this module reads them once.

use std::collections::HashMap;
use std::sync::OnceLock;

pub const GLYPH_W: usize = 7;
pub const GLYPH_H: usize = 14;

/// One glyph's coverage, row-major, 0 (empty) to 15 (full).
pub type Glyph = [u8; GLYPH_W * GLYPH_H];

const DATA: &str = include_str!("font.txt");

/// The glyph of `ch`, or of '?' for a character the font does not have.
pub fn glyph(ch: char) -> Option<&'static Glyph> {
    let all = glyphs();
    all.get(&ch).or_else(|| all.get(&'?'))
}

fn glyphs() -> &'static HashMap<char, Glyph> {
    static GLYPHS: OnceLock<HashMap<char, Glyph>> = OnceLock::new();
    GLYPHS.get_or_init(|| parse(DATA))
}

/// "U+XXXX" then 14 rows of 7 hex digits, per glyph; `#` lines are comments. The file is
/// generated and compiled in, so a malformed glyph is skipped rather than reported.
fn parse(text: &str) -> HashMap<char, Glyph> {
    let mut out = HashMap::new();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    while let Some(head) = lines.next() {
        let Some(ch) = head
            .strip_prefix("U+")
            .and_then(|h| u32::from_str_radix(h, 16).ok())
            .and_then(char::from_u32)
        else {
            continue;
        };
        let mut g = [0u8; GLYPH_W * GLYPH_H];
        let mut ok = true;
        for r in 0..GLYPH_H {
            let row = lines.next().unwrap_or("");
            let px: Vec<u8> = row
                .chars()
                .filter_map(|c| c.to_digit(16).map(|d| d as u8))
                .collect();
            if px.len() != GLYPH_W {
                ok = false;
                break;
            }
            g[r * GLYPH_W..(r + 1) * GLYPH_W].copy_from_slice(&px);
        }
        if ok {
            out.insert(ch, g);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_glyph_the_figures_use_is_there() {
        let all = glyphs();
        let used = (0x20u8..0x7f)
            .map(char::from)
            .chain("ψ′±°−·—βμωσχ×≤≥→".chars());
        for ch in used {
            assert!(all.contains_key(&ch), "{ch:?} missing from font.txt");
        }
        // Not blank: 'A' covers some pixels fully, a space none.
        assert!(glyph('A').unwrap().contains(&15));
        assert!(glyph(' ').unwrap().iter().all(|&p| p == 0));
        assert_eq!(glyph('\u{1F600}'), glyph('?'));
    }
}
