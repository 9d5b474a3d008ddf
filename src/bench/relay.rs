//! `impactcam bench relay`: latency and jitter of relay pulses over a serial line, against a
//! module emulator on a pseudo-terminal. For each protocol, N pulses of the configured length;
//! printed: the pulse length the module saw minus the one requested (median, p99, max) and the
//! delay from the request to fire to the module seeing the relay close.

use crate::config::{RelayProtocol, TriggerConfig};
use crate::trigger::serial::SerialRelay;
use crate::trigger::{CameraLive, Trigger};
use hw_sim::modules::{Emulator, Kind};
use std::fmt::Write as _;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

fn quantiles(mut v: Vec<f64>) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    (q(0.5), q(0.99), v[v.len() - 1])
}

pub fn relay(pulses: usize, pulse_ms: f64) -> Result<String, String> {
    let mut out = String::new();
    let _ = writeln!(out, "impactcam bench relay — {pulses} pulses of {pulse_ms} ms per protocol, module emulated on a pseudo-terminal");
    let _ = writeln!(
        out,
        "{:<8} {:>34} {:>34}",
        "",
        "pulse seen − requested, ms (med p99 max)",
        "request → module sees close, ms (med p99 max)"
    );
    for (name, protocol, kind, channel) in [
        ("lcus", RelayProtocol::Lcus, Kind::Lcus, 1u8),
        ("numato", RelayProtocol::Numato, Kind::Numato, 0),
    ] {
        let emu = Emulator::start(kind).map_err(|e| e.to_string())?;
        let cfg = TriggerConfig {
            protocol,
            channel,
            relay_pulse_ms: pulse_ms,
            ..TriggerConfig::default()
        };
        let relay = SerialRelay::open(&cfg, emu.path(), "serial").map_err(|e| e.to_string())?;
        let trigger = Trigger::new(Box::new(relay), pulse_ms, cfg.relay_pulse_ms_max);
        let mut fired = Vec::new();
        for _ in 0..pulses {
            // From the request, not from `closed_at`: a verifying protocol (Numato) stamps that
            // only after the module has confirmed.
            fired.push(std::time::Instant::now());
            let p = trigger
                .fire(&CameraLive::confirmed(3), Arc::new(AtomicBool::new(false)))
                .map_err(|e| e.to_string())?;
            p.finish().map_err(|e| e.to_string())?;
        }
        let switches = emu.switches();
        let closes: Vec<_> = switches.iter().filter(|s| s.1).map(|s| s.0).collect();
        let mut held = Vec::new();
        for w in switches.windows(2) {
            if w[0].1 && !w[1].1 {
                held.push((w[1].0 - w[0].0).as_secs_f64() * 1e3 - pulse_ms);
            }
        }
        let latency: Vec<f64> = closes
            .iter()
            .zip(&fired)
            .map(|(seen, f)| seen.saturating_duration_since(*f).as_secs_f64() * 1e3)
            .collect();
        if held.is_empty() || latency.is_empty() {
            return Err(format!("{name}: the emulated module saw no complete pulse"));
        }
        let (h, l) = (quantiles(held), quantiles(latency));
        let _ = writeln!(
            out,
            "{name:<8} {:>10.3} {:>10.3} {:>10.3}   {:>10.3} {:>10.3} {:>10.3}",
            h.0, h.1, h.2, l.0, l.1, l.2
        );
        let _ = writeln!(
            out,
            "{:<8} pulse error at the median: {:.4} of the requested {pulse_ms} ms",
            "",
            h.0 / pulse_ms
        );
    }
    Ok(out)
}
