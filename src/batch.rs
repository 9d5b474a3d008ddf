//! Many sessions at once (`replay` and `analyze` given several paths): which sessions the paths
//! name, the shard of them this process takes (`--shard i/n`, for a cluster's array job), and
//! running one job per session on N threads, results in the sessions' order whatever finished
//! first. The reduce step of a cluster re-analysis is `impactcam fit`; nothing here schedules
//! across machines.

use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    #[error("{0}: {1}")]
    Path(PathBuf, String),
    #[error(
        "--shard {0:?}: expected i/n with 0 ≤ i < n, e.g. 3/16 (Slurm: $SLURM_ARRAY_TASK_ID/16)"
    )]
    Shard(String),
}

/// Whether `dir` is a recorded session (it has a manifest).
pub fn is_session(dir: &Path) -> bool {
    dir.join("session.json").is_file()
}

/// Whether `dir` holds sessions (directly, or in its `sessions/` as a campaign does).
pub fn holds_sessions(dir: &Path) -> bool {
    let inner = dir.join("sessions");
    let scan = if inner.is_dir() {
        inner
    } else {
        dir.to_path_buf()
    };
    std::fs::read_dir(scan).is_ok_and(|entries| {
        entries
            .filter_map(|e| e.ok())
            .any(|e| is_session(&e.path()))
    })
}

/// The sessions `paths` name, sorted and each once: a session directory is itself; a campaign
/// directory gives the sessions in its `sessions/`; any other directory, the sessions directly
/// inside it (a sessions directory). A path that is none of these is an error naming it.
pub fn sessions(paths: &[PathBuf]) -> Result<Vec<PathBuf>, BatchError> {
    let mut out = Vec::new();
    for p in paths {
        if is_session(p) {
            out.push(p.clone());
            continue;
        }
        let dir = if p.join("sessions").is_dir() {
            p.join("sessions")
        } else {
            p.clone()
        };
        let entries = std::fs::read_dir(&dir).map_err(|e| {
            BatchError::Path(
                p.clone(),
                format!("expected a session, a campaign or a sessions directory: {e}"),
            )
        })?;
        let found: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|d| is_session(d))
            .collect();
        if found.is_empty() {
            return Err(BatchError::Path(
                p.clone(),
                "no session in it (a session directory holds session.json)".into(),
            ));
        }
        out.extend(found);
    }
    out.sort();
    out.dedup();
    Ok(out)
}

/// `--shard i/n`: of the sessions in order, those at positions i, i + n, i + 2n, …
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl FromStr for Shard {
    type Err = BatchError;
    fn from_str(s: &str) -> Result<Shard, BatchError> {
        let bad = || BatchError::Shard(s.to_string());
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl Shard {
    /// This shard's share of `items`.
    pub fn select<T: Clone>(&self, items: &[T]) -> Vec<T> {
        items
            .iter()
            .skip(self.index)
            .step_by(self.count)
            .cloned()
            .collect()
    }
}

/// What a batch will run: this shard's sessions, of how many found, on how many threads.
pub struct Plan {
    pub sessions: Vec<PathBuf>,
    pub found: usize,
    pub jobs: usize,
}

/// The sessions `paths` name, this shard of them, and the threads to run them on (`jobs`, 0:
/// every core): each analysis on one thread, sessions side by side — a lone session gets every
/// thread for its frames (`analysis::set_threads`).
pub fn plan(paths: &[PathBuf], shard: Option<Shard>, jobs: usize) -> Result<Plan, BatchError> {
    let all = sessions(paths)?;
    let mine = match shard {
        Some(s) => s.select(&all),
        None => all.clone(),
    };
    let jobs = match jobs {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    };
    crate::analysis::set_threads(if mine.len() == 1 { jobs } else { 1 });
    Ok(Plan {
        sessions: mine,
        found: all.len(),
        jobs,
    })
}

/// What a replay of one session found.
#[derive(Debug, PartialEq)]
pub enum ReplayOutcome {
    Identical,
    Differs,
    NoRecord,
    Failed(String),
}

impl std::fmt::Display for ReplayOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReplayOutcome::Identical => write!(f, "identical"),
            ReplayOutcome::Differs => write!(f, "DIFFERS from the recorded report.json"),
            ReplayOutcome::NoRecord => write!(f, "no report.json to compare with"),
            ReplayOutcome::Failed(e) => write!(f, "error: {e}"),
        }
    }
}

/// Analyses `session` again with its own config and compares the report's bytes with the
/// recorded one.
pub fn replay_one(session: &Path) -> ReplayOutcome {
    match crate::experiment::analyze_session(session, None, &mut |_, _| {}) {
        Err(e) => ReplayOutcome::Failed(e.to_string()),
        Ok(report) => match std::fs::read_to_string(session.join("report.json")) {
            Ok(r) if r == crate::experiment::report_json(&report) => ReplayOutcome::Identical,
            Ok(_) => ReplayOutcome::Differs,
            Err(_) => ReplayOutcome::NoRecord,
        },
    }
}

/// Analyses `session` with its own config (or `config`) and writes its report.json (atomically).
pub fn analyze_one(session: &Path, config: Option<&crate::config::Config>) -> Result<(), String> {
    let report = crate::experiment::analyze_session(session, config, &mut |_, _| {})
        .map_err(|e| e.to_string())?;
    crate::session::write_atomic(
        &session.join("report.json"),
        crate::experiment::report_json(&report).as_bytes(),
    )
    .map_err(|e| e.to_string())
}

/// Runs `job` on every item on `jobs` threads (the calling one among them) and returns the
/// results in the items' order. `done` is called as each item finishes, on the thread that ran
/// it but under a lock, with (item, its result, how many are done now): progress lines come
/// out whole, in the order of completion.
pub fn run<T: Send>(
    items: &[PathBuf],
    jobs: usize,
    job: impl Fn(&Path) -> T + Sync,
    done: impl FnMut(&Path, &T, usize) + Send,
) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<T>>> = Mutex::new((0..items.len()).map(|_| None).collect());
    let done = Mutex::new((done, 0usize));
    let work = || loop {
        let k = next.fetch_add(1, Ordering::Relaxed);
        let Some(item) = items.get(k) else { break };
        let r = job(item);
        if let Ok(mut d) = done.lock() {
            d.1 += 1;
            let n = d.1;
            (d.0)(item, &r, n);
        }
        if let Ok(mut res) = results.lock() {
            res[k] = Some(r);
        }
    };
    std::thread::scope(|scope| {
        for _ in 1..jobs.clamp(1, items.len().max(1)) {
            scope.spawn(work);
        }
        work();
    });
    results
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .flatten()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_split_the_sessions_and_bad_ones_are_named() {
        let items: Vec<usize> = (0..10).collect();
        let all: Vec<usize> = (0..3)
            .flat_map(|i| Shard { index: i, count: 3 }.select(&items))
            .collect();
        let mut sorted = all.clone();
        sorted.sort();
        assert_eq!(sorted, items, "every item in exactly one shard");
        assert_eq!(
            "1/3".parse::<Shard>().unwrap().select(&items),
            vec![1, 4, 7]
        );
        for bad in ["3/3", "1/0", "a/2", "2", "-1/4"] {
            let e = bad.parse::<Shard>().unwrap_err().to_string();
            assert!(e.contains(bad) && e.contains("i/n"), "{e}");
        }
    }

    #[test]
    fn results_come_back_in_the_items_order_whatever_the_threads() {
        let items: Vec<PathBuf> = (0..23).map(|i| PathBuf::from(format!("s{i:02}"))).collect();
        for jobs in [1, 2, 7] {
            let mut seen = 0;
            let out = run(
                &items,
                jobs,
                |p| {
                    // Uneven work, so that items finish out of order.
                    let n: usize = p.to_string_lossy()[1..].parse().unwrap_or(0);
                    std::thread::sleep(std::time::Duration::from_micros(
                        ((n * 7) % 5) as u64 * 300,
                    ));
                    p.display().to_string()
                },
                |_, _, k| seen = seen.max(k),
            );
            let want: Vec<String> = items.iter().map(|p| p.display().to_string()).collect();
            assert_eq!(out, want, "jobs {jobs}");
            assert_eq!(seen, items.len());
        }
    }
}
