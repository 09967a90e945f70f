//! Who a process is, and whether it still runs: host name, pid, the pid's start time, and the
//! unique names built from them.
//!
//! Claims, the run lock and temporary directories record their owner so that another process
//! can tell a live owner from a dead one. On the owner's own host that is exact: `/proc/<pid>`
//! exists, is not a zombie, and started at the recorded time (pids are reused; the start time,
//! in clock ticks since boot, is field 22 of `/proc/<pid>/stat`). From another host nothing can
//! be checked, so callers fall back to a lease (the owner's age).

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;
use std::time::{SystemTime, UNIX_EPOCH};

/// This host's name, restricted to `[A-Za-z0-9_.-]` (it becomes part of file names and must never
/// contain the `~` that separates the fields of a unique name).
pub(crate) fn host() -> &'static str {
    static HOST: OnceLock<String> = OnceLock::new();
    HOST.get_or_init(|| {
        let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .or_else(|_| std::fs::read_to_string("/etc/hostname"))
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .unwrap_or_default();
        let clean: String = raw
            .trim()
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-') {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        if clean.is_empty() {
            "unknown-host".to_string()
        } else {
            clean
        }
    })
}

/// The start time of `pid` in clock ticks since boot, when `/proc` tells it.
pub(crate) fn pid_start(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may itself hold spaces and ')', so count
    // fields from the last ')': field 3 (state) is the first after it, field 22 the 20th.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(19)?.parse().ok()
}

/// This process's start time (see [`pid_start`]), read once.
pub(crate) fn own_start() -> Option<u64> {
    static START: OnceLock<Option<u64>> = OnceLock::new();
    *START.get_or_init(|| pid_start(std::process::id()))
}

/// Whether the process `pid` of this host runs and, when `start` is known, is the same process
/// that was recorded (not a later one that reused the pid). Without `/proc` (not Linux) nothing
/// can be told, so every pid counts as alive: a stale owner is then only ever cleared by hand or
/// by a lease, never a live one taken over.
pub(crate) fn alive(pid: u32, start: Option<u64>) -> bool {
    if !Path::new("/proc/self").exists() {
        return true;
    }
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
        return false;
    };
    let rest = match stat.rfind(')') {
        Some(i) => &stat[i + 1..],
        None => return true,
    };
    let mut fields = rest.split_whitespace();
    // A zombie has exited; only its parent has not reaped it yet.
    if matches!(fields.next(), Some("Z") | Some("X")) {
        return false;
    }
    match (start, fields.nth(18).and_then(|s| s.parse::<u64>().ok())) {
        (Some(recorded), Some(now)) => recorded == now,
        _ => true,
    }
}

/// Seconds since the Unix epoch (0 if the clock is before 1970).
pub(crate) fn now_secs() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0)
}

/// A name no other process on any host, and no other call in this process, ever produces:
/// `host~pid~pidstart~counter~nanos`. `~` is not allowed in unit names or host names, so
/// [`parse_unique`] can read the owner back from the end of any name that ends with it.
pub(crate) fn unique() -> String {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    format!(
        "{}~{}~{}~{}~{:x}",
        host(),
        std::process::id(),
        own_start().unwrap_or(0),
        n,
        nanos
    )
}

/// The owner (host, pid, pid start) of a name ending with [`unique`]'s suffix.
pub(crate) fn parse_unique(name: &str) -> Option<(&str, u32, Option<u64>)> {
    let mut parts = name.rsplit('~');
    let _nanos = parts.next()?;
    let _counter = parts.next()?;
    let start: u64 = parts.next()?.parse().ok()?;
    let pid: u32 = parts.next()?.parse().ok()?;
    let host = parts.next()?;
    Some((host, pid, (start != 0).then_some(start)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_process_is_alive_and_a_reaped_child_is_not() {
        assert!(alive(std::process::id(), own_start()));
        assert!(own_start().is_some());
        // The same pid with another start time is a different (earlier) process.
        assert!(!alive(std::process::id(), own_start().map(|s| s + 1)));
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let pid = child.id();
        child.wait().unwrap();
        assert!(!alive(pid, None));
    }

    #[test]
    fn unique_names_differ_and_parse_back() {
        let a = unique();
        let b = unique();
        assert_ne!(a, b);
        let name = format!("unit.m3c2.x~{a}");
        let (h, pid, start) = parse_unique(&name).unwrap();
        assert_eq!(h, host());
        assert_eq!(pid, std::process::id());
        assert_eq!(start, own_start());
        assert!(parse_unique("plain-name").is_none());
    }
}
