//! The sbatch scripts of a submission and `submit.sh`, the sbatch commands that chain them. talus
//! submits with exactly the arguments [`sbatch_args`] gives, which `submit.sh` spells out, so
//! what a reviewer reads (`--plan-only`) is what runs.

use std::path::Path;

use super::record::{task_log_path, Submission};
use crate::error::{Error, Result};

/// A word quoted for a POSIX shell (as is when it needs no quotes).
pub(crate) fn quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+%@".contains(c))
    {
        return s.to_string();
    }
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// The arguments of sbatch for array `k` of `sub`, after `sbatch`: `--parsable`, the dependency
/// on the arrays it waits for (`after`: their job ids, or shell variables in `submit.sh`), the
/// user's `--slurm-args` (after talus's own `#SBATCH` lines, which they override), the script.
pub(crate) fn sbatch_args(sub: &Submission, k: usize, after: &[String]) -> Vec<String> {
    let mut a = vec!["--parsable".to_string()];
    if !after.is_empty() {
        a.push(format!("--dependency=afterok:{}", after.join(":")));
    }
    a.extend(sub.sbatch_args.iter().cloned());
    a.push(sub.stages[k].script.clone());
    a
}

/// The text of array `k`'s script.
fn script(sub: &Submission, dir: &Path, k: usize) -> String {
    let s = &sub.stages[k];
    let n = s.tasks.len();
    let units: usize = s.tasks.iter().map(Vec::len).sum();
    let log = task_log_path(dir, &s.kind, 0);
    let log = log.to_string_lossy().replace("-0.out", "-%a.out");
    let short = &sub.run[..sub.run.len().min(8)];
    let what = if s.kind == super::PUBLISH {
        "publishes the outputs into DIR (takes DIR's lock) and drops old units".to_string()
    } else {
        format!("{units} unit(s) of stage {} in {n} task(s)", s.kind)
    };
    let mut t = format!(
        "#!/bin/bash\n\
         # talus submission {num}, array {k1} of {all}: {what}.\n\
         # Submitted by: {cmd}\n\
         # Task i runs its units (submission.json, stages[{k}].tasks[i]) with `talus slurm-task`,\n\
         # which skips units already done and writes tasks/{kind}-i.json.\n\
         #SBATCH --job-name=talus-{short}-{kind}\n\
         #SBATCH --array=0-{last}\n\
         #SBATCH --output={log}\n\
         #SBATCH --kill-on-invalid-dep=yes\n",
        num = sub.number,
        k1 = k + 1,
        all = sub.stages.len(),
        cmd = sub.command.replace('\n', " "),
        kind = s.kind,
        last = n - 1,
    );
    // The publishing job alone takes 1 GiB; one that computes tails the arrays left (its task's
    // units) takes what any task does.
    if s.kind == super::PUBLISH && s.tasks.iter().all(|t| t.is_empty()) {
        t.push_str("#SBATCH --mem=1024M\n");
    } else {
        t.push_str(&format!("#SBATCH --mem={}M\n", sub.mem_mib));
        if let Some(c) = sub.cpus {
            t.push_str(&format!("#SBATCH --cpus-per-task={c}\n"));
        }
    }
    t.push_str(&format!(
        "exec {} slurm-task {} --submission {} --stage {}\n",
        quote(&sub.talus.to_string_lossy()),
        quote(&sub.dir.to_string_lossy()),
        sub.number,
        s.kind
    ));
    t
}

/// `submit.sh`: the chain of sbatch commands, and jobs.json written as talus writes it.
fn submit_sh(sub: &Submission) -> String {
    let mut t = format!(
        "#!/bin/bash\n\
         # The sbatch commands of talus submission {}: each array after the arrays holding what\n\
         # its units read (afterok; --kill-on-invalid-dep=yes in the scripts). talus runs exactly these unless\n\
         # --plan-only; after review, this script submits the same jobs and records their ids.\n\
         set -euo pipefail\n\
         cd \"$(dirname \"${{BASH_SOURCE[0]}}\")\"\n",
        sub.number
    );
    for k in 0..sub.stages.len() {
        let after: Vec<String> = sub.stages[k]
            .after
            .iter()
            .map(|j| format!("$j{}", j + 1))
            .collect();
        let args: Vec<String> = sbatch_args(sub, k, &after)
            .iter()
            .map(|a| {
                if a.contains("$j") {
                    format!("\"{a}\"")
                } else {
                    quote(a)
                }
            })
            .collect();
        t.push_str(&format!(
            "j{n}=$(sbatch {}); j{n}=${{j{n}%%;*}}\n",
            args.join(" "),
            n = k + 1
        ));
    }
    let ids: Vec<String> = (1..=sub.stages.len())
        .map(|n| format!("\\\"$j{n}\\\""))
        .collect();
    t.push_str(&format!(
        "printf '%s\\n' \"{{\\\"ids\\\": [{}]}}\" > jobs.json\n",
        ids.join(", ")
    ));
    let echo: Vec<String> = (1..=sub.stages.len()).map(|n| format!("$j{n}")).collect();
    t.push_str(&format!("echo {}\n", echo.join(" ")));
    t
}

/// Write every script of `sub` into its directory `dir`.
pub(crate) fn write(dir: &Path, sub: &Submission) -> Result<()> {
    use std::os::unix::fs::PermissionsExt;
    let mut files: Vec<(String, String)> = (0..sub.stages.len())
        .map(|k| (sub.stages[k].script.clone(), script(sub, dir, k)))
        .collect();
    files.push(("submit.sh".into(), submit_sh(sub)));
    for (name, text) in files {
        let p = dir.join(&name);
        std::fs::write(&p, text).map_err(|e| Error::output(&p, e))?;
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755))
            .map_err(|e| Error::output(&p, e))?;
    }
    Ok(())
}
