//! Campaigns on the page: the experiments under the sessions directory grouped by the campaign
//! name in their manifests (`config.experiment.campaign`, set by the Run form or a config), and
//! for one campaign the same fit as `impactcam fit` over its analysed sessions — e, μ, β0, the
//! ψ2–ψ1 plot with both Walton lines, the table and its CSV. Computed on request from what is on
//! disk, so it grows as experiments finish and survives a restart of the daemon.

use super::{error, Shared};
use crate::campaign::{self, fit};
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::{json, Value};
use std::collections::BTreeMap;

/// The most sessions looked at for campaigns (newest names first), as for `/api/sessions`.
const MAX_SESSIONS_SCANNED: usize = 10_000;

/// `GET /api/campaigns`: each campaign's name and how many sessions carry it.
pub(super) async fn list(State(state): State<Shared>) -> Response {
    let dir = state.cfg.recording.dir.clone();
    let counts = tokio::task::spawn_blocking(move || {
        let mut counts: BTreeMap<String, usize> = BTreeMap::new();
        for (_, label) in campaign::labelled_sessions(&dir, MAX_SESSIONS_SCANNED) {
            if let Some(name) = label.campaign {
                *counts.entry(name).or_default() += 1;
            }
        }
        counts
    })
    .await
    .unwrap_or_default();
    let list: Vec<Value> = counts
        .into_iter()
        .map(|(name, n)| json!({"name": name, "sessions": n}))
        .collect();
    Json(json!({ "campaigns": list })).into_response()
}

/// What one campaign's routes compute: the collisions of its analysed sessions and their fit,
/// the sessions skipped (and why), and each session's notes.
struct Computed {
    collisions: Vec<fit::Collision>,
    fit: fit::CampaignFit,
    skipped: Vec<String>,
    notes: BTreeMap<String, String>,
}

async fn compute(state: &Shared, name: String) -> Result<Computed, Response> {
    if !crate::config::is_campaign_name(&name) {
        return Err(error(
            StatusCode::BAD_REQUEST,
            format!("{name:?} is not a campaign name: expected 1 to 64 characters of A-Z a-z 0-9 . _ - and inner spaces"),
        ));
    }
    let dir = state.cfg.recording.dir.clone();
    let result = tokio::task::spawn_blocking(move || {
        let labelled = campaign::sessions_in_campaign(&dir, &name, MAX_SESSIONS_SCANNED);
        if labelled.is_empty() {
            return Err((
                StatusCode::NOT_FOUND,
                format!("no session in the sessions directory belongs to campaign {name:?}"),
            ));
        }
        let notes: BTreeMap<String, String> = labelled
            .iter()
            .filter_map(|(p, l)| {
                Some((
                    p.file_name()?.to_string_lossy().into_owned(),
                    l.notes.clone()?,
                ))
            })
            .collect();
        let sessions: Vec<_> = labelled.into_iter().map(|(p, _)| p).collect();
        let mut skipped = Vec::new();
        // A session of another material, or a report that is not a report, is the lab's to see:
        // the same refusal `impactcam fit` gives.
        let mut collisions = campaign::load(&sessions, &mut skipped)
            .map_err(|e| (StatusCode::UNPROCESSABLE_ENTITY, e.to_string()))?;
        // The error text names paths; the page shows names within the sessions directory.
        let base = format!("{}/", dir.display());
        for s in &mut skipped {
            *s = s.replace(&base, "");
        }
        let f = fit::fit(&mut collisions);
        Ok(Computed {
            collisions,
            fit: f,
            skipped,
            notes,
        })
    })
    .await;
    match result {
        Ok(Ok(c)) => Ok(c),
        Ok(Err((status, message))) => Err(error(status, message)),
        Err(e) => Err(error(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("campaign fit failed: {e}"),
        )),
    }
}

/// `GET /api/campaigns/{name}`: the fit as `impactcam fit --json` gives it (e, mu, beta0,
/// psi1_break with uncertainties and 95 % intervals, the per-collision rows), the sessions
/// skipped, and each session's notes.
pub(super) async fn one(State(state): State<Shared>, Path(name): Path<String>) -> Response {
    match compute(&state, name.clone()).await {
        Ok(c) => Json(json!({
            "name": name,
            "fit": campaign::fit_json(&c.fit),
            "skipped": c.skipped,
            "notes": c.notes,
        }))
        .into_response(),
        Err(r) => r,
    }
}

/// `GET /api/campaigns/{name}/psi.svg`: the ψ2–ψ1 plot with the fitted Walton lines.
pub(super) async fn psi_svg(State(state): State<Shared>, Path(name): Path<String>) -> Response {
    match compute(&state, name).await {
        Ok(c) => {
            let (svg, _) = campaign::plot::psi_plot(&c.collisions, &c.fit);
            ([("content-type", "image/svg+xml")], svg).into_response()
        }
        Err(r) => r,
    }
}

/// `GET /api/campaigns/{name}/collisions.csv`: the table, as `fit` writes it.
pub(super) async fn csv(State(state): State<Shared>, Path(name): Path<String>) -> Response {
    match compute(&state, name.clone()).await {
        Ok(c) => (
            [
                ("content-type", "text/csv; charset=utf-8".to_string()),
                (
                    "content-disposition",
                    // The name is checked above: no quote or control character can reach here.
                    format!("attachment; filename=\"{}.csv\"", name.replace(' ', "_")),
                ),
            ],
            campaign::csv(&c.collisions),
        )
            .into_response(),
        Err(r) => r,
    }
}
