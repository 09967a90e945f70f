//! The small commands: `synth`, `view` and `demo`, wired over the library's stages.

use std::net::IpAddr;
use std::path::Path;

use crate::error::{Error, Result};

/// `talus synth SCENE --out DIR`.
#[allow(clippy::too_many_arguments)]
pub fn synth(
    scene: &str,
    out: &Path,
    points: Option<u64>,
    seed: u64,
    noise: Option<f64>,
    rotate: f64,
    density2: f64,
    laz: bool,
) -> Result<()> {
    let _ = (scene, out, points, seed, noise, rotate, density2, laz);
    Err(Error::Internal("synth is being merged".into()))
}

/// `talus view DIR`.
pub fn view(dir: &Path, bind: IpAddr, port: u16) -> Result<()> {
    let _ = (dir, bind, port);
    Err(Error::Internal("view is being merged".into()))
}

/// `talus demo`.
pub fn demo(out: &Path, view: bool) -> Result<()> {
    let _ = (out, view);
    Err(Error::Internal("demo is being merged".into()))
}
