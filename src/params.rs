//! Parameters of a comparison: what the user gave (flags over config file) and what talus derives
//! from the data, each recorded with where it came from (written to summary.json).
//!
//! Derivation rules, all from the effective point spacing `s` = 1/√density of C1 (measured, see
//! [`crate::sampling`]: the side of the square one point covers; a cylinder of radius r holds
//! ≈ π r² / s² points whatever the point pattern):
//!
//! | parameter | rule | why |
//! |---|---|---|
//! | core_spacing | 2 s | cylinders (radius 3 s) of neighbouring core points overlap a little: no gaps, few repeats |
//! | normal_radius | 4 s | ≈ 50 points in the disc: a stable plane fit that still follows a metre-scale scar at 0.1 m spacing |
//! | cyl_radius | 3 s | ≈ 28 points per cylinder and epoch, about the 30 Lague et al. recommend for a stable mean |
//! | cyl_halflen | 10 × cyl_radius | reaches changes of ≈ 30 s along the normal without catching far surfaces |
//! | reg_error | measured: RMS of n·t on the stable ground | the registration error the distances show where nothing changed (`crate::events::stable`) |
//! | min_points | 1 | SPEC.md §1 default |
//! | threshold τ | 3 σ_d + 1.96 reg_error | a change must exceed the noise of one distance on stable ground (σ_d) and the registration error (the paper's §3.3); 3 σ because neighbouring distances share cylinder points, so 1.96 σ excursions form clusters of 10+ core points on stable ground (7 spurious events on the clean cliff scene, none at 3 σ); s / 2 when there is no stable ground to measure |
//! | smooth_k | 30 | the paper's value |
//! | smooth_sigma | 2 × core_spacing | the k = 30 neighbours reach ≈ 3 core spacings; weights fall off over that reach |
//! | eps | 2.5 × core_spacing | joins neighbouring core points (also diagonal ones, √2 × spacing) with room for a missing one |
//! | cluster_min_points | 10 | the paper's value |

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::io::classes::Classes;
use crate::io::Bounds;
use crate::m3c2::{M3c2Params, Orientation};

/// Values the user set, by flag or config file; `None` = derive.
#[derive(Debug, Clone, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct UserParams {
    /// The effective point spacing the derivation rules start from (default: measured on C1).
    pub point_spacing: Option<f64>,
    pub core_spacing: Option<f64>,
    pub normal_radius: Option<f64>,
    pub cyl_radius: Option<f64>,
    pub cyl_halflen: Option<f64>,
    pub reg_error: Option<f64>,
    pub min_points: Option<u32>,
    /// The LAS classes compared: `all` or a list (default: all but vegetation 3, 4, 5 and
    /// noise 7, 18).
    pub classes: Option<String>,
    /// Stable areas the user knows (`--stable AREAS.geojson`): the stable ground is the core
    /// points inside their polygons (default: found in the distances).
    pub stable: Option<PathBuf>,
    pub orientation: Option<String>,
    /// `auto` (align the later survey on the stable ground when it is a plausible
    /// misregistration that holds out of sample), `on` (whatever its size) or `off`.
    pub align: Option<String>,
    /// `keep`, `flag` or `remove` (SPEC.md §4 "Vegetation").
    pub vegetation: Option<String>,
    pub threshold: Option<f64>,
    pub smooth_k: Option<u32>,
    pub smooth_sigma: Option<f64>,
    pub eps: Option<f64>,
    pub cluster_min_points: Option<u32>,
    pub memory: Option<String>,
    pub threads: Option<usize>,
    /// The config file the values came from that no flag overrides; not a key of the file.
    #[serde(skip)]
    pub config: Option<ConfigSource>,
}

/// A config file and the keys whose values are still its own (a flag overrides a key).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConfigSource {
    pub path: PathBuf,
    pub keys: Vec<String>,
}

impl UserParams {
    /// Read a TOML config file (same names as the flags, with underscores).
    pub(crate) fn from_toml_file(path: &Path) -> Result<Self> {
        Self::from_toml_file_with(path, &[]).map(|(u, _)| u)
    }

    /// Read a TOML config file whose top-level tables or arrays named in `sections` are not
    /// parameters (a campaign's `[[epoch]]` entries): they are returned apart, unparsed.
    pub(crate) fn from_toml_file_with(
        path: &Path,
        sections: &[&str],
    ) -> Result<(Self, toml::Table)> {
        // A regular file only: a FIFO would block, `<(…)` is read once (`io::open_file`).
        let mut text = String::new();
        std::io::Read::read_to_string(&mut crate::io::open_file(path)?, &mut text)
            .map_err(|e| Error::input(path, format!("cannot read config: {e}")))?;
        let bad = |e: toml::de::Error| {
            let line = e.span().map_or(String::new(), |s| {
                format!("line {}: ", text[..s.start].matches('\n').count() + 1)
            });
            Error::input(path, format!("bad config: {line}{}", e.message()))
        };
        let mut table: toml::Table = toml::from_str(&text).map_err(bad)?;
        let mut apart = toml::Table::new();
        for name in sections {
            if let Some(v) = table.remove(*name) {
                apart.insert(name.to_string(), v);
            }
        }
        let user: std::result::Result<UserParams, _> = toml::Value::Table(table.clone()).try_into();
        let mut user = match user {
            Ok(u) => u,
            // Errors from a value carry no position: find the key that fails alone and name its line.
            Err(e) => {
                let key = table.iter().find_map(|(k, v)| {
                    let one = toml::Table::from_iter([(k.clone(), v.clone())]);
                    toml::Value::Table(one)
                        .try_into::<UserParams>()
                        .err()
                        .map(|_| k)
                });
                let line = key.and_then(|k| {
                    text.lines().position(|l| {
                        l.trim_start()
                            .strip_prefix(k.as_str())
                            .is_some_and(|r| r.trim_start().starts_with('='))
                    })
                });
                let at = line.map_or(String::new(), |n| format!("line {}: ", n + 1));
                return Err(Error::input(
                    path,
                    format!("bad config: {at}{}", e.message()),
                ));
            }
        };
        // The file's own keys (a value serde_json cannot hold, like nan, would vanish from
        // `keys_set` and be blamed on a flag the user never passed).
        let mut keys = user.keys_set();
        for k in table.keys() {
            if !keys.contains(k) {
                keys.push(k.clone());
            }
        }
        user.config = Some(ConfigSource {
            path: path.to_path_buf(),
            keys,
        });
        Ok((user, apart))
    }

    /// The names of the values that are set.
    fn keys_set(&self) -> Vec<String> {
        match serde_json::to_value(self) {
            Ok(serde_json::Value::Object(m)) => m
                .into_iter()
                .filter(|(_, v)| !v.is_null())
                .map(|(k, _)| k)
                .collect(),
            _ => Vec::new(),
        }
    }

    /// The error for a bad value of `key`: it names the config file and the key when the value
    /// came from there, else the flag.
    pub(crate) fn bad_value(&self, key: &str, problem: impl std::fmt::Display) -> Error {
        match &self.config {
            Some(c) if c.keys.iter().any(|k| k == key) => {
                Error::input(&c.path, format!("{key}: {problem}"))
            }
            _ => Error::Usage(format!("--{}: {problem}", key.replace('_', "-"))),
        }
    }

    /// The LAS classes the user asked for (the default when none): known before the
    /// parameters are resolved, since the spacing they start from is measured on those points.
    pub(crate) fn classes(&self) -> Result<Classes> {
        match self.classes.as_deref() {
            None => Ok(Classes::default()),
            Some(c) => Classes::parse(c).map_err(|p| self.bad_value("classes", p)),
        }
    }

    /// Refuse lengths far beyond the data: more than `MAX_EXTENT_FACTOR` times the diagonal of
    /// the epochs' bounds. A neighbourhood that wide holds every point (no use), and the work
    /// that grows with it (the volume grid over a footprint grown by `cyl_radius`, neighbour
    /// lists) would run for hours instead of failing.
    pub fn check_lengths_within(&self, bounds: &[Bounds]) -> Result<()> {
        let mut all = Bounds::empty();
        for b in bounds {
            all.grow(&b.min);
            all.grow(&b.max);
        }
        let diagonal = (0..3)
            .map(|k| (all.max[k] - all.min[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let limit = MAX_EXTENT_FACTOR * diagonal.max(MIN_LENGTH);
        for (key, v) in self.lengths() {
            if let Some(x) = v.filter(|&x| x > limit) {
                return Err(self.bad_value(
                    key,
                    format!(
                        "{} is more than {MAX_EXTENT_FACTOR} times the data's extent \
                         ({diagonal:.3}, the diagonal of the epochs' bounds)",
                        num(x)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The lengths that size neighbourhoods, with their keys.
    fn lengths(&self) -> [(&'static str, Option<f64>); 7] {
        [
            ("point_spacing", self.point_spacing),
            ("core_spacing", self.core_spacing),
            ("normal_radius", self.normal_radius),
            ("cyl_radius", self.cyl_radius),
            ("cyl_halflen", self.cyl_halflen),
            ("smooth_sigma", self.smooth_sigma),
            ("eps", self.eps),
        ]
    }

    /// `self` (flags) over `base` (config file).
    pub(crate) fn over(self, base: UserParams) -> UserParams {
        let flags = self.keys_set();
        let config = base.config.map(|mut c| {
            c.keys.retain(|k| !flags.contains(k));
            c
        });
        UserParams {
            point_spacing: self.point_spacing.or(base.point_spacing),
            core_spacing: self.core_spacing.or(base.core_spacing),
            normal_radius: self.normal_radius.or(base.normal_radius),
            cyl_radius: self.cyl_radius.or(base.cyl_radius),
            cyl_halflen: self.cyl_halflen.or(base.cyl_halflen),
            reg_error: self.reg_error.or(base.reg_error),
            min_points: self.min_points.or(base.min_points),
            classes: self.classes.or(base.classes),
            stable: self.stable.or(base.stable),
            orientation: self.orientation.or(base.orientation),
            align: self.align.or(base.align),
            vegetation: self.vegetation.or(base.vegetation),
            threshold: self.threshold.or(base.threshold),
            smooth_k: self.smooth_k.or(base.smooth_k),
            smooth_sigma: self.smooth_sigma.or(base.smooth_sigma),
            eps: self.eps.or(base.eps),
            cluster_min_points: self.cluster_min_points.or(base.cluster_min_points),
            memory: self.memory.or(base.memory),
            threads: self.threads.or(base.threads),
            config,
        }
    }
}

/// One resolved parameter and where it came from.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Resolved<T> {
    pub value: T,
    /// "user" (flag or config file) or `"derived: <rule>"` or "default".
    pub source: String,
}

/// Every parameter of a run, resolved.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Params {
    /// The effective point spacing (1/√density of C1, measured) the rules start from.
    pub point_spacing: Resolved<f64>,
    pub core_spacing: Resolved<f64>,
    pub normal_radius: Resolved<f64>,
    pub cyl_radius: Resolved<f64>,
    pub cyl_halflen: Resolved<f64>,
    pub reg_error: Resolved<f64>,
    pub min_points: Resolved<u32>,
    /// The LAS classes compared ([`crate::io::classes::Classes`]'s words). Absent from a plan
    /// written before it existed: all.
    #[serde(default = "classes_all")]
    pub classes: Resolved<String>,
    pub orientation: Resolved<String>,
    /// `auto` or `off` (SPEC.md §1 "Registration: removed, not only measured"). Absent from a
    /// plan written before it existed: off.
    #[serde(default = "align_off")]
    pub align: Resolved<String>,
    /// What vegetation events count for (SPEC.md §4). Absent from a plan written before it
    /// existed: keep.
    #[serde(default = "vegetation_keep")]
    pub vegetation: Resolved<Vegetation>,
    pub threshold: Resolved<f64>,
    pub smooth_k: Resolved<u32>,
    pub smooth_sigma: Resolved<f64>,
    pub eps: Resolved<f64>,
    pub cluster_min_points: Resolved<u32>,
    pub memory_bytes: Resolved<u64>,
    pub threads: Resolved<usize>,
}

/// The source of a parameter the user gave (a flag or the config file).
pub(crate) const USER: &str = "user";

fn classes_all() -> Resolved<String> {
    Resolved {
        value: "all".into(),
        source: "default of an older plan".into(),
    }
}

fn vegetation_keep() -> Resolved<Vegetation> {
    Resolved {
        value: Vegetation::Keep,
        source: "default of an older plan".into(),
    }
}

/// What talus does with vegetation (`--vegetation`, SPEC.md §4 "Vegetation").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Vegetation {
    /// Events are judged (`vegetation_fraction`, `vegetation`) and count like any other.
    Keep,
    /// Vegetation events are listed but left out of totals, campaign sums, tracks and the
    /// magnitude–frequency fit (the default).
    Flag,
    /// Vegetation-like points are dropped before M3C2; what is left of vegetation events is
    /// flagged as with `flag`.
    Remove,
}

impl Vegetation {
    /// Whether an event counts in totals, campaign sums, tracks and the magnitude–frequency fit:
    /// every event but a vegetation one kept apart (`flag`, `remove`).
    pub(crate) fn counts(self, vegetation_event: bool) -> bool {
        self == Vegetation::Keep || !vegetation_event
    }
}

impl std::fmt::Display for Vegetation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Vegetation::Keep => "keep",
            Vegetation::Flag => "flag",
            Vegetation::Remove => "remove",
        })
    }
}

fn align_off() -> Resolved<String> {
    Resolved {
        value: "off".into(),
        source: "default of an older plan".into(),
    }
}

impl<T> Resolved<T> {
    /// A value the user gave.
    pub(crate) fn user(value: T) -> Resolved<T> {
        Resolved {
            value,
            source: USER.into(),
        }
    }

    /// Whether the user gave it (else it was derived, measured or a default).
    pub(crate) fn is_user(&self) -> bool {
        self.source == USER
    }
}

fn pick<T: Copy>(user: Option<T>, derived: T, rule: &str) -> Resolved<T> {
    match user {
        Some(v) => Resolved::user(v),
        None => Resolved {
            value: derived,
            source: rule.into(),
        },
    }
}

/// The shortest length a user may give: a micrometre in metre units. Shorter ones are not a
/// survey's scale, and they would push the exact sums' quantisation (`m3c2::moments`) and the
/// column grid towards subnormal numbers.
pub(crate) const MIN_LENGTH: f64 = 1e-6;

/// The longest length a user may give: a million kilometres in metre units, beyond any survey
/// (longer ones overflow the halo and grid arithmetic to infinity).
pub(crate) const MAX_LENGTH: f64 = 1e9;

/// See [`UserParams::check_lengths_within`].
pub(crate) const MAX_EXTENT_FACTOR: f64 = 10.0;

/// The most worker threads accepted. Results do not depend on the thread count, so more threads
/// than cores only cost memory (a stack and tile buffers each); 1024 is beyond any machine talus
/// runs on, and a typo like 100000 is refused rather than obeyed (or silently changed).
pub(crate) const MAX_THREADS: usize = 1024;

/// Check a length the user gave: finite and positive (or zero, when `zero_ok`), and within
/// [`MIN_LENGTH`] (unless zero) ..= [`MAX_LENGTH`].
fn check_length(user: &UserParams, name: &str, v: Option<f64>, zero_ok: bool) -> Result<()> {
    let Some(x) = v else { return Ok(()) };
    let problem = if !(x.is_finite() && (x > 0.0 || (zero_ok && x == 0.0))) {
        let what = if zero_ok {
            "zero or positive"
        } else {
            "a positive number"
        };
        format!("must be {what}, got {}", num(x))
    } else if x != 0.0 && x < MIN_LENGTH {
        format!(
            "{} is below the shortest length talus accepts ({MIN_LENGTH})",
            num(x)
        )
    } else if x > MAX_LENGTH {
        format!(
            "{} is beyond the longest length talus accepts ({MAX_LENGTH:e})",
            num(x)
        )
    } else {
        return Ok(());
    };
    Err(user.bad_value(name, problem))
}

/// A number for a message: plain when of everyday size, else in exponent form (`1e300`).
fn num(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-4..1e7).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// The threshold τ in robust standard deviations of the stable ground's distances (see the
/// table above).
pub(crate) const THRESHOLD_SIGMAS: f64 = 3.0;

/// Default memory budget (SPEC.md §3).
pub(crate) const DEFAULT_MEMORY: u64 = 2 << 30;

/// Parse a size like `2GiB`, `512MiB`, `1.5G`, `800M`, `4096` (bytes); the problem alone, for
/// the caller to say whose value it was.
fn parse_size_problem(s: &str) -> std::result::Result<u64, String> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let bad = || format!("cannot read '{s}' as a size (e.g. 2GiB, 512MiB)");
    let n: f64 = num.parse().map_err(|_| bad())?;
    let mul = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" | "kib" => 1024.0,
        "m" | "mb" | "mib" => 1024.0 * 1024.0,
        "g" | "gb" | "gib" => 1024.0 * 1024.0 * 1024.0,
        "t" | "tb" | "tib" => 1024.0_f64.powi(4),
        _ => return Err(bad()),
    };
    let bytes = n * mul;
    if bytes.is_nan() || bytes < crate::memory::MIN_BUDGET as f64 {
        return Err(format!(
            "{s} is too small; talus needs at least {}MiB (the outputs' writers beside the process)",
            crate::memory::mib(crate::memory::MIN_BUDGET)
        ));
    }
    Ok(bytes as u64)
}

impl Params {
    /// Resolve every parameter from the user's values and the measured spacing (used unless
    /// the user gave `point_spacing`).
    pub fn resolve(user: &UserParams, measured_spacing: f64) -> Result<Params> {
        for (name, v) in user.lengths() {
            check_length(user, name, v, false)?;
        }
        check_length(user, "reg_error", user.reg_error, true)?;
        check_length(user, "threshold", user.threshold, true)?;
        for (name, v) in [
            ("smooth_k", user.smooth_k),
            ("cluster_min_points", user.cluster_min_points),
        ] {
            if v == Some(0) {
                return Err(user.bad_value(name, "must be at least 1"));
            }
        }
        if user.min_points == Some(0) {
            // It was taken as 1 in silence: a cylinder without a point gives no distance.
            return Err(user.bad_value(
                "min_points",
                "must be at least 1 (a cylinder without a point of an epoch gives no distance)",
            ));
        }
        match user.threads {
            Some(0) => return Err(user.bad_value("threads", "must be at least 1")),
            Some(n) if n > MAX_THREADS => {
                return Err(user.bad_value(
                    "threads",
                    format!("{n} is more than talus accepts ({MAX_THREADS})"),
                ))
            }
            _ => {}
        }
        let align = match user.align.as_deref() {
            None => Resolved {
                value: "auto".to_string(),
                source: "default: auto".into(),
            },
            Some(a @ ("auto" | "on" | "off")) => Resolved::user(a.to_string()),
            Some(other) => {
                return Err(user.bad_value("align", format!("auto, on or off, not '{other}'")));
            }
        };
        let vegetation = match user.vegetation.as_deref() {
            None => Resolved {
                value: Vegetation::Flag,
                source: "default: flag (SPEC.md §4)".into(),
            },
            Some("keep") => Resolved::user(Vegetation::Keep),
            Some("flag") => Resolved::user(Vegetation::Flag),
            Some("remove") => Resolved::user(Vegetation::Remove),
            Some(other) => {
                return Err(
                    user.bad_value("vegetation", format!("keep, flag or remove, not '{other}'"))
                );
            }
        };
        let classes = match user.classes {
            None => Resolved {
                value: Classes::default().to_string(),
                source: "default: vegetation (3, 4, 5) and noise (7, 18) left out (SPEC.md §4)"
                    .into(),
            },
            Some(_) => Resolved::user(user.classes()?.to_string()),
        };
        let orientation = user.orientation.clone().unwrap_or_else(|| "auto".into());
        orientation.parse::<Orientation>().map_err(|m| {
            let problem = m.strip_prefix("--orientation: ").unwrap_or(&m);
            user.bad_value("orientation", problem)
        })?;
        let point_spacing = pick(
            user.point_spacing,
            measured_spacing,
            "measured: 1/√density of the before survey",
        );
        let s = point_spacing.value;
        if !(s > 0.0 && s.is_finite()) {
            return Err(Error::Internal(format!(
                "point spacing {s} is not positive"
            )));
        }
        let core_spacing = pick(user.core_spacing, 2.0 * s, "derived: 2 × effective spacing");
        let c = core_spacing.value;
        let cyl_radius = pick(user.cyl_radius, 3.0 * s, "derived: 3 × effective spacing");
        let memory = match &user.memory {
            Some(m) => {
                Resolved::user(parse_size_problem(m).map_err(|p| user.bad_value("memory", p))?)
            }
            None => Resolved {
                value: DEFAULT_MEMORY,
                source: "default: 2GiB".into(),
            },
        };
        let threads_default = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1);
        Ok(Params {
            point_spacing,
            normal_radius: pick(
                user.normal_radius,
                4.0 * s,
                "derived: 4 × effective spacing",
            ),
            cyl_halflen: pick(
                user.cyl_halflen,
                10.0 * cyl_radius.value,
                "derived: 10 × cyl_radius",
            ),
            cyl_radius,
            // Both measured on the stable ground once M3C2 has run (`with_stable`).
            reg_error: pick(
                user.reg_error,
                0.0,
                "measured by a comparison on its stable ground",
            ),
            min_points: pick(user.min_points, 1, "default: 1 (SPEC.md §1)"),
            classes,
            orientation: Resolved {
                source: if user.orientation.is_some() {
                    USER.into()
                } else {
                    "default: auto".into()
                },
                value: orientation,
            },
            align,
            vegetation,
            threshold: pick(
                user.threshold,
                0.5 * s,
                "measured by a comparison on its stable ground",
            ),
            smooth_k: pick(user.smooth_k, 30, "default: 30 (the paper's value)"),
            smooth_sigma: pick(user.smooth_sigma, 2.0 * c, "derived: 2 × core_spacing"),
            eps: pick(user.eps, 2.5 * c, "derived: 2.5 × core_spacing"),
            cluster_min_points: pick(
                user.cluster_min_points,
                10,
                "default: 10 (the paper's value)",
            ),
            core_spacing,
            memory_bytes: memory,
            threads: pick(user.threads, threads_default, "default: available cores"),
        })
    }

    /// Refuse a core spacing so much finer than the surveys' points that no event can form:
    /// every point is a core point, and the DBSCAN radius derived from it (2.5 × core_spacing)
    /// is shorter than the gap between points (one effective spacing), so it joins no two of
    /// them — every change would come out as no event, in silence. A core spacing below the
    /// point spacing with `--eps` given is the user's choice (every point a core point).
    pub(crate) fn check_core_spacing(&self, user: &UserParams) -> Result<()> {
        let (c, s) = (self.core_spacing.value, self.point_spacing.value);
        if self.eps.is_user() || self.eps.value >= s {
            return Ok(());
        }
        Err(user.bad_value(
            "core_spacing",
            format!(
                "{c} is far finer than the surveys' points (effective spacing {s:.4}): every \
                 point would be a core point, and the DBSCAN radius derived from it (--eps = 2.5 \
                 × core spacing = {:.3e}) joins no two of them, so no event could form; give a \
                 core spacing of at least {:.4} (0.4 × the spacing), or --eps too",
                self.eps.value,
                0.4 * s
            ),
        ))
    }

    /// The registration error and threshold the user left out, from the stable ground's
    /// measurement (or, without one, 0 and half the effective spacing).
    pub(crate) fn with_stable(mut self, stable: Option<&crate::events::stable::Stable>) -> Params {
        if !self.reg_error.is_user() {
            self.reg_error = match stable {
                Some(m) => Resolved {
                    value: m.reg_error,
                    source: format!(
                        "measured: RMS of n·t over {} stable core points, t = ({:.4}, {:.4}, {:.4})",
                        m.stable_points, m.translation[0], m.translation[1], m.translation[2]
                    ),
                },
                None => Resolved {
                    value: 0.0,
                    source: "default: 0 (too few stable core points to measure it)".into(),
                },
            };
        }
        if !self.threshold.is_user() {
            let reg = self.reg_error.value;
            self.threshold = match stable {
                Some(m) => Resolved {
                    value: THRESHOLD_SIGMAS * m.sigma_d + 1.96 * reg,
                    source: format!(
                        "derived: 3 σ_d + 1.96 reg_error, σ_d = {:.4} the robust spread of the distances on stable ground",
                        m.sigma_d
                    ),
                },
                None => Resolved {
                    value: 0.5 * self.point_spacing.value,
                    source: "derived: effective spacing / 2 (no stable ground to measure noise on)"
                        .into(),
                },
            };
        }
        self
    }

    /// The M3C2 part.
    pub fn m3c2(&self) -> M3c2Params {
        M3c2Params {
            normal_radius: self.normal_radius.value,
            cyl_radius: self.cyl_radius.value,
            cyl_halflen: self.cyl_halflen.value,
            min_points: self.min_points.value,
            point_spacing: self.point_spacing.value,
            orientation: self
                .orientation
                .value
                .parse()
                .expect("validated in resolve"),
            walk: self.walk(),
        }
    }

    /// The LAS classes compared.
    pub(crate) fn classes(&self) -> Classes {
        // Written by `resolve` from a parsed value (or "all" for an older plan).
        Classes::parse(&self.classes.value).unwrap_or_default()
    }

    /// Whether later surveys are aligned onto the first on the stable ground (`--align auto` or
    /// `on`).
    pub(crate) fn align_enabled(&self) -> bool {
        matches!(self.align.value.as_str(), "auto" | "on")
    }

    /// How far an alignment may move a survey: a plausible misregistration (`auto`), or any the
    /// stable ground fixes (`on`).
    pub(crate) fn align_limits(&self) -> crate::events::align::Limits {
        if self.align.value == "on" {
            crate::events::align::Limits::FORCED
        } else {
            crate::events::align::Limits::PLAUSIBLE
        }
    }

    /// How M3C2 treats a cylinder that holds only one epoch ([`crate::m3c2::reach`]): a derived
    /// half-length is a search window and the other epoch is sought on along the normal; the
    /// user's half-length is kept, and what lies beyond it is flagged, not measured.
    pub(crate) fn walk(&self) -> crate::m3c2::Walk {
        if self.cyl_halflen.is_user() {
            crate::m3c2::Walk::Detect
        } else {
            crate::m3c2::Walk::Measure
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes() {
        assert_eq!(parse_size_problem("2GiB").unwrap(), 2 << 30);
        assert_eq!(parse_size_problem("512MiB").unwrap(), 512 << 20);
        assert_eq!(parse_size_problem("1.5G").unwrap(), 3 << 29);
        assert!(parse_size_problem("abc").is_err());
        assert!(parse_size_problem("1MiB").is_err());
    }

    #[test]
    fn derivation_and_overrides() {
        let user = UserParams {
            cyl_radius: Some(0.5),
            ..Default::default()
        };
        let p = Params::resolve(&user, 0.1).unwrap();
        assert_eq!(p.cyl_radius.value, 0.5);
        assert!(p.cyl_radius.is_user());
        assert!((p.normal_radius.value - 0.4).abs() < 1e-12);
        assert!((p.cyl_halflen.value - 5.0).abs() < 1e-12);
        assert!(p.normal_radius.source.starts_with("derived"));
        let bad = UserParams {
            normal_radius: Some(-1.0),
            ..Default::default()
        };
        assert!(matches!(
            Params::resolve(&bad, 0.1),
            Err(Error::Usage(m)) if m.contains("--normal-radius")
        ));
        let tiny = UserParams {
            cyl_radius: Some(5e-324),
            ..Default::default()
        };
        assert!(matches!(
            Params::resolve(&tiny, 0.1),
            Err(Error::Usage(m)) if m.contains("--cyl-radius") && m.contains("shortest")
        ));
    }

    #[test]
    fn flags_over_config() {
        let cfg: UserParams = toml::from_str("cyl_radius = 2.0\neps = 3.0").unwrap();
        let flags = UserParams {
            cyl_radius: Some(1.0),
            ..Default::default()
        };
        let m = flags.over(cfg);
        assert_eq!(m.cyl_radius, Some(1.0));
        assert_eq!(m.eps, Some(3.0));
        assert!(toml::from_str::<UserParams>("bogus = 1").is_err());
    }
}
