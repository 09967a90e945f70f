//! Claims: `claims/<run>/<kind>/<name>` says which process computes a unit right now, so that
//! the threads of a run, `talus worker` processes and Slurm tasks on other hosts do not all
//! compute the same unit.
//!
//! A claim only saves work; correctness never depends on it: units are deterministic and a
//! second commit of the same unit keeps the first (see [`UnitWriter::commit`]). That is why a
//! claim from another host, whose pid cannot be checked, may be taken over after a lease: its
//! process renews every claim it holds every [`RENEW_EVERY`] (a thread of the store), so a claim
//! not renewed for [`super::DEFAULT_LEASE`] is one whose process (or node) is gone. And a Slurm
//! task requeued after its node failed takes over at once the claims of its earlier attempt
//! ([`Store::claim_attempt`]): Slurm runs one attempt of a task at a time.
//!
//! [`UnitWriter::commit`]: super::UnitWriter::commit

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use talus_base::{Error, Result};

use super::fsops::{no_links, out_err, read_store_file};
use super::owner_file::{self, Acquired, Owner};
use super::unit_ref::{check_component, UnitRef};
use super::Store;

/// The content of a claim file.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClaimInfo {
    #[serde(flatten)]
    pub owner: Owner,
    /// Who claims, in the caller's words ("thread 3", "slurm 1234_7").
    pub label: String,
    /// For a label that one attempt at a time runs as (a Slurm array task), which attempt
    /// (Slurm's restart count): a later attempt takes the claims of an earlier one over.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attempt: Option<u32>,
}

/// How often a process renews the claims it holds (see the module doc).
pub const RENEW_EVERY: Duration = Duration::from_secs(60);

/// The claims this process holds, renewed by [`renewer`]: their paths, content and `tmp/`.
static HELD: Mutex<Vec<(PathBuf, ClaimInfo, PathBuf)>> = Mutex::new(Vec::new());

fn held() -> std::sync::MutexGuard<'static, Vec<(PathBuf, ClaimInfo, PathBuf)>> {
    HELD.lock().unwrap_or_else(|e| e.into_inner())
}

/// Start, once per process, the thread that renews the held claims every [`RENEW_EVERY`]. A
/// renewal rewrites a claim still ours (its token) with `renewed` = now, atomically (temporary,
/// rename); failing to renew one only lets it expire.
fn renewer() {
    static START: std::sync::Once = std::sync::Once::new();
    START.call_once(|| {
        let _ = std::thread::Builder::new()
            .name("talus claims".into())
            .spawn(|| loop {
                std::thread::sleep(RENEW_EVERY);
                let now = super::process::now_secs();
                // Under the lock, which a claim's release also takes: a claim released meanwhile
                // is never written again.
                let claims = held();
                for (path, info, tmp) in claims.iter() {
                    let mut renewed = info.clone();
                    renewed.owner.renewed = Some(now);
                    if let Ok(bytes) = claim_bytes(&renewed) {
                        let _ = owner_file::renew(path, tmp, &info.owner.token, &bytes);
                    }
                }
            });
    });
}

/// A held claim; dropping it removes the claim file.
#[derive(Debug)]
pub struct Claim {
    path: PathBuf,
    info: ClaimInfo,
}

impl Store {
    /// Claim `unit` for this process in run `run` (see the module doc). `None` when a live claim
    /// of another process — or of another thread of this one — holds it. A claim whose owner on
    /// this host is dead, or from another host older than the lease, is taken over.
    pub fn claim(&self, run: &str, unit: &UnitRef, label: &str) -> Result<Option<Claim>> {
        self.claim_as(run, unit, label, None)
    }

    /// [`Store::claim`] for attempt `attempt` of a task that runs one attempt at a time, labelled
    /// `label` in every attempt (a Slurm array task, `attempt` its `SLURM_RESTART_COUNT`): a
    /// claim of an earlier attempt of the same label, from whichever host, is taken over — that
    /// attempt has ended (its node failed and Slurm requeued the task), though its host may not
    /// be able to say so for a lease.
    pub fn claim_attempt(
        &self,
        run: &str,
        unit: &UnitRef,
        label: &str,
        attempt: u32,
    ) -> Result<Option<Claim>> {
        self.claim_as(run, unit, label, Some(attempt))
    }

    fn claim_as(
        &self,
        run: &str,
        unit: &UnitRef,
        label: &str,
        attempt: Option<u32>,
    ) -> Result<Option<Claim>> {
        check_component("run id", run)?;
        unit.check()?;
        let rel = Path::new("claims").join(run).join(&unit.kind);
        let dir = self.work.join(&rel);
        // No link on the way: a claim taken over is moved away and deleted, and a planted
        // `claims/<run>` → elsewhere would make that a file outside DIR.
        no_links(&self.work, &rel)?;
        std::fs::create_dir_all(&dir).map_err(out_err(&dir))?;
        no_links(&self.work, &rel)?;
        let path = dir.join(&unit.name);
        let info = ClaimInfo {
            owner: Owner::me(),
            label: label.to_string(),
            attempt,
        };
        let bytes = claim_bytes(&info)?;
        let lease = self.lease;
        let earlier = |b: &[u8]| {
            serde_json::from_slice::<ClaimInfo>(b).is_ok_and(|c| {
                c.label == label
                    && matches!((c.attempt, attempt), (Some(theirs), Some(ours)) if theirs < ours)
            })
        };
        match owner_file::acquire(&path, &self.tmp(), &bytes, |b, mtime| {
            Owner::stale(b, mtime, Some(lease)) || earlier(b)
        })? {
            Acquired::Ours => {
                renewer();
                held().push((path.clone(), info.clone(), self.tmp()));
                Ok(Some(Claim { path, info }))
            }
            Acquired::Held(_) => Ok(None),
        }
    }

    /// Remove every claim, of any run, that `ended` says belongs to a process known to have
    /// ended (the tasks of a Slurm submission Slurm says are over: their host may not be able to
    /// tell, and its claims would hold for a lease). Returns how many were removed.
    pub fn drop_claims(&self, ended: impl Fn(&ClaimInfo) -> bool) -> Result<usize> {
        let mut dropped = 0;
        let claims = self.work.join("claims");
        for run in super::fsops::sorted_names(&claims)? {
            let rel = Path::new("claims").join(&run);
            if check_component("run id", &run).is_err() || no_links(&self.work, &rel).is_err() {
                continue;
            }
            for kind in super::fsops::sorted_names(&self.work.join(&rel))? {
                // Never through a planted link: what is removed must be inside DIR.
                let kind_rel = rel.join(&kind);
                let dir = self.work.join(&kind_rel);
                if check_component("unit kind", &kind).is_err()
                    || no_links(&self.work, &kind_rel).is_err()
                    || !dir.is_dir()
                {
                    continue;
                }
                for name in super::fsops::sorted_names(&dir)? {
                    let path = dir.join(&name);
                    let Some(info) = read_store_file(&path)
                        .ok()
                        .and_then(|b| serde_json::from_slice::<ClaimInfo>(&b).ok())
                    else {
                        continue;
                    };
                    if ended(&info) && owner_file::release(&path, &info.owner.token)? {
                        dropped += 1;
                    }
                }
            }
        }
        Ok(dropped)
    }

    /// The current claim on `unit` in run `run`, if any (live or not: for `talus status`).
    pub fn claim_holder(&self, run: &str, unit: &UnitRef) -> Option<ClaimInfo> {
        check_component("run id", run).ok()?;
        unit.check().ok()?;
        let rel = Path::new("claims").join(run).join(&unit.kind);
        no_links(&self.work, &rel).ok()?;
        let path = self.work.join(rel).join(&unit.name);
        serde_json::from_slice(&read_store_file(&path).ok()?).ok()
    }
}

fn claim_bytes(info: &ClaimInfo) -> Result<Vec<u8>> {
    serde_json::to_vec_pretty(info).map_err(|e| Error::Internal(format!("claim: {e}")))
}

#[cfg(test)]
impl Claim {
    /// The claim file (the tests look at it).
    pub(crate) fn path(&self) -> &std::path::Path {
        &self.path
    }
}

impl Drop for Claim {
    fn drop(&mut self) {
        let mut held = held();
        held.retain(|(_, info, _)| info.owner.token != self.info.owner.token);
        let _ = owner_file::release(&self.path, &self.info.owner.token);
    }
}
