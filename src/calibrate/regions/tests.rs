use super::*;

/// A disc of diameter `d` px at (u, v), covering the pixels within d/2 − 1 of its centre
/// (a threshold at half the contrast stops short of the blurred edge).
fn disc(u: f64, v: f64, d: f64) -> Blob {
    let r = 0.5 * d - 1.0;
    let px = |x: f64| x.round().max(0.0) as usize;
    Blob {
        centroid: [u, v],
        area_px: (std::f64::consts::PI * 0.25 * d * d).round() as usize,
        extent_px: [px(u - r), px(v - r), px(u + r), px(v + r)],
        clipped: false,
        merged: false,
    }
}

fn blob(u: f64, v: f64) -> Blob {
    disc(u, v, 14.0)
}

/// Two spheres falling in the top view (rows 10–80), the same x in a flat band below.
fn two_views(edge: f64) -> Vec<Vec<Blob>> {
    (0..30)
        .map(|k| {
            let t = k as f64;
            let (ua, ub) = (60.0 + 2.0 * t, 180.0 - 2.0 * t);
            let v = 10.0 + 0.07 * t * t;
            vec![
                blob(ua, v),
                blob(ub, v + 3.0),
                blob(0.97 * ua + 4.0, edge + 40.0),
                blob(0.97 * ub + 4.0, edge + 42.0),
            ]
        })
        .collect()
}

#[test]
fn the_edge_is_where_the_background_steps_within_the_gap() {
    let blobs = two_views(96.0);
    let gaps = gaps(&blobs, true, 192);
    assert_eq!(gaps.len(), 1, "{gaps:?}");
    // A step of 3 grey levels down at row 96 (entry 95: row 96 less row 95), ±0.1 elsewhere.
    let profile: Vec<f64> = (1..192)
        .map(|v| {
            if v == 96 {
                -3.0
            } else {
                0.1 * ((v * 7 % 5) as f64 - 2.0)
            }
        })
        .collect();
    let s = split_at(&blobs, true, gaps[0], &profile, Side::Before).unwrap();
    assert_eq!(s.edge_px, 96);
    assert!(s.step_grey.is_some());
    assert_eq!(s.regions(240, 192), ([0, 0, 240, 96], [0, 96, 240, 96]));
    // The direct view below: the same edge, the regions swapped.
    let below = split_at(&blobs, true, gaps[0], &profile, Side::After).unwrap();
    assert_eq!(below.regions(240, 192), ([0, 96, 240, 96], [0, 0, 240, 96]));
    // Without a step, the edge closes on the direct view's spheres: the lowest reaches
    // v = 10 + 0.07·29² + 3 + 6 = 77.9 (less the survey's 1 px of slack); the mirror's top
    // at 130.
    let flat: Vec<f64> = (1..192).map(|v| 0.1 * ((v * 7 % 5) as f64 - 2.0)).collect();
    let s = split_at(&blobs, true, gaps[0], &flat, Side::Before).unwrap();
    assert!(s.step_grey.is_none());
    assert_eq!(s.edge_px, 79, "{s:?}");
    // Spheres cut off at the edge (smaller blobs against the gap) on the mirror's side
    // put it there instead.
    let mut cut = blobs.clone();
    for (k, f) in cut.iter_mut().enumerate().take(3) {
        f.push(disc(100.0 + k as f64, 131.0, 6.0));
    }
    let gaps_cut = super::gaps(&cut, true, 192);
    let s = split_at(&cut, true, gaps_cut[0], &flat, Side::Before).unwrap();
    assert_eq!(s.cut_side, Some(Side::After));
    // The cut blobs' tops at 131 − 2 = 129 (less the slack).
    assert_eq!(s.edge_px, 129, "{s:?}");
}

/// The same two views from a camera turned on its side: side by side, the edge a column,
/// x down the rows. The sides pair by their coordinate along the edge (v here); paired by u,
/// across it, as before, they did not follow one line and no edge was found.
#[test]
fn side_by_side_views_pair_along_their_edge() {
    let turned: Vec<Vec<Blob>> = two_views(96.0)
        .iter()
        .map(|f| {
            f.iter()
                .map(|b| disc(b.centroid[1], b.centroid[0], 14.0))
                .collect()
        })
        .collect();
    let gaps = gaps(&turned, false, 240);
    assert_eq!(gaps.len(), 1, "{gaps:?}");
    let profile: Vec<f64> = (1..240)
        .map(|u| {
            if u == 96 {
                -3.0
            } else {
                0.1 * ((u * 7 % 5) as f64 - 2.0)
            }
        })
        .collect();
    let s = split_at(&turned, false, gaps[0], &profile, Side::Before).unwrap();
    assert_eq!(s.edge_px, 96);
    assert_eq!(s.regions(192, 240), ([0, 0, 96, 240], [96, 0, 96, 240]));
}

#[test]
fn sides_that_do_not_share_x_are_not_two_views() {
    // Two spheres one above the other, moving apart in x: no straight line maps one's u to
    // the other's.
    let blobs: Vec<Vec<Blob>> = (0..30)
        .map(|k| {
            let t = k as f64;
            vec![
                blob(120.0 + 3.0 * (t * 0.7).sin() * 20.0, 30.0),
                blob(40.0 + 0.1 * t * t, 150.0),
            ]
        })
        .collect();
    let profile = vec![10.0; 192];
    let found = gaps(&blobs, true, 192);
    // There is a gap between the two rows of spheres: the check below is not vacuous.
    assert!(!found.is_empty());
    for gap in found {
        assert!(split_at(&blobs, true, gap, &profile, Side::Before).is_none());
    }
}

#[test]
fn regions_typed_across_a_view_do_not_separate_its_spheres() {
    let s = Survey {
        blobs: two_views(96.0),
        split: None,
    };
    assert!(s.separates(&[[0, 0, 240, 96], [0, 96, 240, 96]]));
    // The edge at row 60 cuts through the falling spheres.
    assert!(!s.separates(&[[0, 0, 240, 60], [0, 60, 240, 132]]));
    // One region over the whole frame holds everything but leaves the other empty.
    assert!(!s.separates(&[[0, 0, 240, 192], [0, 192, 240, 0]]));
}
