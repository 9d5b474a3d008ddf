//! Config validation: every key's range and the relations between keys, checked before
//! anything is opened. Each error names the key and what was expected; every size a recording
//! allocates by is bounded here.

use super::*;

impl Config {
    /// Range and consistency checks; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        let c = &self.camera;
        let pos = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!(
                    "{key}: {v} is not allowed, expected a positive number"
                ))
            }
        };
        pos("camera.frame_rate_hz", c.frame_rate_hz)?;
        if c.frame_rate_hz > 1.0e6 {
            return Err(format!(
                "camera.frame_rate_hz: {} is out of range, expected at most 1000000",
                c.frame_rate_hz
            ));
        }
        if c.width == 0 || c.height == 0 || c.width > 16384 || c.height > 16384 {
            return Err(format!(
                "camera.width/height: {}×{} is out of range, expected 1 to 16384 px each",
                c.width, c.height
            ));
        }
        if let Some(e) = c.exposure_us {
            pos("camera.exposure_us", e)?;
        }
        if let Some(g) = c.gamma {
            if !(g.is_finite() && (0.2..=5.0).contains(&g)) {
                return Err(format!(
                    "camera.gamma: {g} is out of range, expected 0.2 to 5 (2.2 for an sRGB-like curve, 1 for linear)"
                ));
            }
        }
        if c.trigger_mode != CameraTrigger::FreeRun && c.backend != CameraBackend::Aravis {
            return Err(format!(
                "camera.trigger_mode: {:?} needs backend = \"aravis\"; other backends run free",
                c.trigger_mode
            ));
        }
        let t = &self.trigger;
        pos("trigger.relay_pulse_ms", t.relay_pulse_ms)?;
        pos("trigger.relay_pulse_ms_max", t.relay_pulse_ms_max)?;
        if t.relay_pulse_ms > t.relay_pulse_ms_max {
            return Err(format!(
                "trigger.relay_pulse_ms: {} exceeds trigger.relay_pulse_ms_max = {}",
                t.relay_pulse_ms, t.relay_pulse_ms_max
            ));
        }
        if t.relay_pulse_ms_max > 10_000.0 {
            return Err(format!(
                "trigger.relay_pulse_ms_max: {} is out of range, expected at most 10000",
                t.relay_pulse_ms_max
            ));
        }
        if t.backend == TriggerBackend::Serial && t.port.is_empty() {
            return Err("trigger.port: missing, expected the relay module's serial device (e.g. \"/dev/ttyUSB0\") for backend = \"serial\"".into());
        }
        if t.channel == 0 && t.protocol == RelayProtocol::Lcus {
            return Err(
                "trigger.channel: 0 is not allowed for protocol = \"lcus\", expected 1 or more"
                    .into(),
            );
        }
        if t.protocol == RelayProtocol::Generic {
            for (key, v) in [
                ("generic_on_hex", &t.generic_on_hex),
                ("generic_off_hex", &t.generic_off_hex),
            ] {
                if v.as_deref()
                    .and_then(parse_hex)
                    .is_none_or(|b| b.is_empty())
                {
                    return Err(format!("trigger.{key}: missing or not hex bytes, expected e.g. \"A0 01 01 A2\" for protocol = \"generic\""));
                }
            }
        }
        if let Some(r) = &t.generic_reply_hex {
            if parse_hex(r).is_none() {
                return Err(format!("trigger.generic_reply_hex: {r:?} is not hex bytes"));
            }
        }
        let r = &self.recording;
        if r.frames < 2 {
            return Err(format!(
                "recording.frames: {} is too few, expected at least 2",
                r.frames
            ));
        }
        if r.frames > MAX_FRAMES {
            return Err(format!(
                "recording.frames: {} is out of range, expected at most {MAX_FRAMES}",
                r.frames
            ));
        }
        if r.pre_trigger_frames >= r.frames {
            return Err(format!(
                "recording.pre_trigger_frames: {} must be less than recording.frames = {}",
                r.pre_trigger_frames, r.frames
            ));
        }
        if r.ram_buffer_mb == 0 || r.ram_buffer_mb > MAX_RAM_BUFFER_MB {
            return Err(format!(
                "recording.ram_buffer_mb: {} is out of range, expected 1 to {MAX_RAM_BUFFER_MB} MiB",
                r.ram_buffer_mb
            ));
        }
        // The pre-trigger ring holds whole frames in memory, inside the RAM buffer.
        let frame_bytes =
            u64::from(c.width) * u64::from(c.height) * c.pixel_format.bytes_per_pixel() as u64;
        let ring_bytes = u64::from(r.pre_trigger_frames) * frame_bytes;
        if ring_bytes > u64::from(r.ram_buffer_mb) << 20 {
            return Err(format!(
                "recording.pre_trigger_frames: {} frames of {}×{} take {} MiB, more than recording.ram_buffer_mb = {}",
                r.pre_trigger_frames,
                c.width,
                c.height,
                ring_bytes.div_ceil(1 << 20),
                r.ram_buffer_mb
            ));
        }
        if r.arm_timeout_ms > MAX_ARM_TIMEOUT_MS {
            return Err(format!(
                "recording.arm_timeout_ms: {} is out of range, expected at most {MAX_ARM_TIMEOUT_MS}",
                r.arm_timeout_ms
            ));
        }
        if self.geometry.direct.is_none() && self.geometry.mirror.is_none() {
            return Err(
                "geometry: no view given, expected [geometry.direct] and/or [geometry.mirror]"
                    .into(),
            );
        }
        for (key, v, plane) in views_of(&self.geometry) {
            let [u0, v0, w, h] = v.region;
            let (u_end, v_end) = (u64::from(u0) + u64::from(w), u64::from(v0) + u64::from(h));
            if w == 0 || h == 0 || u_end > u64::from(c.width) || v_end > u64::from(c.height) {
                return Err(format!(
                    "{key}.region: {:?} does not fit in the {}×{} frame, expected [u, v, width, height] inside it",
                    v.region, c.width, c.height
                ));
            }
            check_view(&key, v, plane)?;
        }
        for i in 0..2 {
            let (d, m) = self.spheres.sphere(i);
            let which = if i == 0 { "a" } else { "b" };
            pos(&format!("spheres.{which}.diameter_mm"), d)?;
            pos(&format!("spheres.{which}.mass_g"), m)?;
        }
        let k = self.spheres.inertia_factor;
        if !(k.is_finite() && k > 0.0 && k <= 2.0 / 3.0) {
            return Err(format!(
                "spheres.inertia_factor: {k} is out of range, expected above 0 and at most 2/3 (a thin shell; 2/5 for a solid sphere)"
            ));
        }
        let a = &self.analysis;
        if a.min_frames_per_side < 2 {
            return Err(format!(
                "analysis.min_frames_per_side: {} is too few, expected at least 2",
                a.min_frames_per_side
            ));
        }
        pos("analysis.gravity_mm_s2", a.gravity_mm_s2)?;
        pos("analysis.marker_diameter_mm", a.marker_diameter_mm)?;
        if !(a.threshold_fraction > 0.05 && a.threshold_fraction < 0.95) {
            return Err(format!(
                "analysis.threshold_fraction: {} is out of range, expected 0.05 to 0.95",
                a.threshold_fraction
            ));
        }
        if let Some(t) = &self.daemon.token {
            check_token(t).map_err(|e| format!("daemon.token: {e}"))?;
        }
        self.sim.validate()?;
        let x = &self.experiment;
        if let Some(name) = &x.campaign {
            if !is_campaign_name(name) {
                return Err(format!(
                    "experiment.campaign: {name:?} is not allowed, expected 1 to 64 characters of A-Z a-z 0-9 . _ - and inner spaces"
                ));
            }
        }
        if let Some(a) = x.tube_angle_deg {
            if !(a.is_finite() && a.abs() <= 90.0) {
                return Err(format!(
                    "experiment.tube_angle_deg: {a} is out of range, expected -90 to 90"
                ));
            }
        }
        if let Some(n) = &x.notes {
            if n.chars().count() > MAX_NOTES_CHARS {
                return Err(format!(
                    "experiment.notes: {} characters, expected at most {MAX_NOTES_CHARS}",
                    n.chars().count()
                ));
            }
        }
        Ok(())
    }
}

/// A view's map, its uncertainties and its lens (not its region, which needs the frame's size):
/// `depth_axis` the world axis the view looks along (2 direct, 1 mirror).
fn check_view(key: &str, v: &ViewGeometry, depth_axis: usize) -> Result<(), String> {
    check_view_map(key, v, depth_axis)?;
    check_geometry_uncertainty(key, v)?;
    check_lens(key, v)
}

/// Every view's `check_view`, as `Config::validate` makes them: what a geometry written for a
/// config (by calibrate) must pass to be read back.
pub(crate) fn check_geometry(g: &Geometry) -> Result<(), String> {
    for (key, v, plane) in views_of(g) {
        check_view(&key, v, plane)?;
    }
    Ok(())
}

/// The views a geometry gives, direct first: each one's key, map and the world axis it looks
/// along (2 direct, 1 mirror).
fn views_of(g: &Geometry) -> impl Iterator<Item = (String, &ViewGeometry, usize)> {
    [("direct", &g.direct, 2), ("mirror", &g.mirror, 1)]
        .into_iter()
        .filter_map(|(name, view, plane)| Some((format!("geometry.{name}"), view.as_ref()?, plane)))
}

/// How well a view's map is known: a scale within 20 % and turns within 10° (a map known worse
/// than that is not a map; the re-run that carries it into the estimates is linear only for
/// small steps).
fn check_geometry_uncertainty(key: &str, v: &ViewGeometry) -> Result<(), String> {
    if let Some(p) = v.px_per_mm_uncertainty_percent {
        if !(p.is_finite() && (0.0..=20.0).contains(&p)) {
            return Err(format!(
                "{key}.px_per_mm_uncertainty_percent: {p} is out of range, expected 0 to 20 (one σ of the scale, %)"
            ));
        }
    }
    if let Some(t) = v.turn_uncertainty_deg {
        if !t.iter().all(|d| d.is_finite() && (0.0..=10.0).contains(d)) {
            return Err(format!(
                "{key}.turn_uncertainty_deg: {t:?} is out of range, expected three numbers from 0 to 10 (one σ of the turn about world x, y, z, deg)"
            ));
        }
    }
    Ok(())
}

/// A view's lens: all three keys or none; |k1| ≤ 0.2 (the fractional displacement at distance
/// `lens_radius_px`; more than that and the distortion may fold within the frame), a centre
/// and a positive radius in px.
fn check_lens(key: &str, v: &ViewGeometry) -> Result<(), String> {
    let given = [
        v.lens_k1.is_some(),
        v.lens_centre_px.is_some(),
        v.lens_radius_px.is_some(),
    ];
    if given.iter().all(|g| !g) {
        return Ok(());
    }
    let (Some(k1), Some(c), Some(r)) = (v.lens_k1, v.lens_centre_px, v.lens_radius_px) else {
        return Err(format!(
            "{key}.lens_k1, {key}.lens_centre_px, {key}.lens_radius_px: give all three or none (the lens's radial distortion, its centre and the distance at which k1 is the fractional displacement, px)"
        ));
    };
    if !(k1.is_finite() && (-0.2..=0.2).contains(&k1)) {
        return Err(format!(
            "{key}.lens_k1: {k1} is out of range, expected -0.2 to 0.2 (the fractional displacement at lens_radius_px; negative: barrel)"
        ));
    }
    if !c.iter().all(|x| x.is_finite() && x.abs() <= 1e5) {
        return Err(format!(
            "{key}.lens_centre_px: {c:?} is not a point, expected two finite numbers (px)"
        ));
    }
    if !(r.is_finite() && (1.0..=1e5).contains(&r)) {
        return Err(format!(
            "{key}.lens_radius_px: {r} is out of range, expected 1 to 100000 (px; the frame's half-diagonal is usual)"
        ));
    }
    Ok(())
}

/// One view's map: exactly one of the three forms, complete, finite, of rank 2, and seeing the
/// world plane its view is for (x–y for the direct view, `depth_axis` 2; x–z for the mirror, 1).
fn check_view_map(key: &str, v: &ViewGeometry, depth_axis: usize) -> Result<(), String> {
    let plane = ["", "z", "y"][depth_axis];
    let shorthand = v.px_per_mm.is_some() || v.u_axis.is_some() || v.v_axis.is_some();
    let forms = [
        shorthand,
        v.matrix_px_per_mm.is_some(),
        v.projection.is_some(),
    ];
    match forms.iter().filter(|f| **f).count() {
        0 => {
            return Err(format!(
                "{key}: no map, expected px_per_mm with u_axis and v_axis, or matrix_px_per_mm, or projection"
            ))
        }
        1 => {}
        _ => {
            let given: Vec<&str> = ["px_per_mm/u_axis/v_axis", "matrix_px_per_mm", "projection"]
                .iter()
                .zip(forms)
                .filter(|(_, f)| *f)
                .map(|(n, _)| *n)
                .collect();
            return Err(format!(
                "{key}: {} given together, expected one of them (the shorthand, an affine matrix or a 3×4 projection)",
                given.join(" and ")
            ));
        }
    }
    if shorthand {
        let (Some(s), Some(o), Some(ua), Some(va)) =
            (v.px_per_mm, v.origin_px, &v.u_axis, &v.v_axis)
        else {
            let missing: Vec<&str> = [
                ("px_per_mm", v.px_per_mm.is_none()),
                ("origin_px", v.origin_px.is_none()),
                ("u_axis", v.u_axis.is_none()),
                ("v_axis", v.v_axis.is_none()),
            ]
            .iter()
            .filter(|(_, m)| *m)
            .map(|(n, _)| *n)
            .collect();
            return Err(format!(
                "{key}.{}: missing, the shorthand needs px_per_mm, origin_px, u_axis and v_axis",
                missing.join(", ")
            ));
        };
        if !(s.is_finite() && s > 0.0) {
            return Err(format!(
                "{key}.px_per_mm: {s} is not allowed, expected a positive number"
            ));
        }
        if !o.iter().all(|x| x.is_finite()) {
            return Err(format!("{key}.origin_px: expected two finite numbers"));
        }
        let pa = parse_axis(ua).ok_or_else(|| {
            format!("{key}.u_axis: {ua:?} is not an axis, expected one of +x -x +y -y +z -z")
        })?;
        let pb = parse_axis(va).ok_or_else(|| {
            format!("{key}.v_axis: {va:?} is not an axis, expected one of +x -x +y -y +z -z")
        })?;
        let uses = |a: [f64; 3], i: usize| a[i] != 0.0;
        let other = 3 - depth_axis; // the plane's axis besides x
        if !(uses(pa, 0) || uses(pa, other))
            || !(uses(pb, 0) || uses(pb, other))
            || pa.iter().zip(pb.iter()).all(|(a, b)| a.abs() == b.abs())
        {
            return Err(format!(
                "{key}: u_axis {ua:?} and v_axis {va:?} must be the two different axes of the world x–{plane} plane this view sees"
            ));
        }
        return Ok(());
    }
    let field = if v.projection.is_some() {
        "projection"
    } else {
        "matrix_px_per_mm"
    };
    if let Some(m) = &v.matrix_px_per_mm {
        if !m.iter().flatten().all(|x| x.is_finite()) {
            return Err(format!(
                "{key}.matrix_px_per_mm: expected 2×3 finite numbers"
            ));
        }
        match v.origin_px {
            None => {
                return Err(format!(
                    "{key}.origin_px: missing, matrix_px_per_mm needs the image of the world origin"
                ))
            }
            Some(o) if !o.iter().all(|x| x.is_finite()) => {
                return Err(format!("{key}.origin_px: expected two finite numbers"))
            }
            _ => {}
        }
    }
    if let Some(p) = &v.projection {
        if !p.iter().flatten().all(|x| x.is_finite()) {
            return Err(format!("{key}.projection: expected 3×4 finite numbers"));
        }
        if v.origin_px.is_some() {
            return Err(format!(
                "{key}.origin_px: not used with projection, whose last column holds the offset; remove it"
            ));
        }
        if p[2][3].abs() <= 1e-12 * p.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max) {
            return Err(format!(
                "{key}.projection: the world origin is on the camera's focal plane (p34 = 0), expected a camera looking at the rig"
            ));
        }
    }
    let Some((m, o)) = v.local_affine() else {
        return Err(format!("{key}: no map"));
    };
    if !m
        .iter()
        .flatten()
        .chain(o.iter())
        .all(|x| x.is_finite() && x.abs() < 1e9)
    {
        return Err(format!(
            "{key}.{field}: its scale or offset at the world origin is not a finite number below 1e9, expected a map of a camera looking at the rig"
        ));
    }
    // The 2×2 minors of M: which world plane the view sees, and whether it sees one at all.
    let minor = |i: usize, j: usize| m[0][i] * m[1][j] - m[0][j] * m[1][i];
    let minors = [(minor(1, 2), 0), (minor(0, 2), 1), (minor(0, 1), 2)]; // (det, depth axis)
    let norm = |r: &[f64; 3]| r.iter().map(|x| x * x).sum::<f64>().sqrt();
    let area = minors.iter().map(|(d, _)| d * d).sum::<f64>().sqrt();
    if area <= 1e-3 * norm(&m[0]) * norm(&m[1]) || area == 0.0 {
        return Err(format!(
            "{key}.{field}: rank below 2 (its rows are parallel or zero), expected a map that images a plane"
        ));
    }
    let (best, along) = minors
        .iter()
        .copied()
        .max_by(|a, b| a.0.abs().total_cmp(&b.0.abs()))
        .unwrap_or((0.0, depth_axis));
    // A view may be turned a few degrees (roll, a tilted mirror), not look along another axis:
    // the world x both views need and this view's own axis must stay well in its image.
    if along != depth_axis || best.abs() < 0.5 * area {
        return Err(format!(
            "{key}.{field}: this view does not see the world x–{plane} plane (it looks along {}), expected the {} view to see x and {plane}",
            ["x", "y", "z"][along],
            if depth_axis == 2 { "direct" } else { "mirror" }
        ));
    }
    Ok(())
}
