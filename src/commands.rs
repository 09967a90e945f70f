//! The small commands: `synth`, `view` and `demo`, wired over the library's stages.

use std::net::IpAddr;
use std::path::Path;

use crate::error::{Error, Result};
use crate::synth::{SceneKind, SynthOptions};

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
    let kind: SceneKind = scene.parse()?;
    let opts = SynthOptions {
        points,
        seed,
        noise,
        rotate_deg: rotate,
        density2,
        laz,
    };
    let truth = crate::synth::synth(kind, &opts, out)?;
    println!(
        "{}: {} + {} points, {} planted event(s), truth in {}",
        truth.scene,
        truth.points[0],
        truth.points[1],
        truth.events.len(),
        out.join("truth.json").display()
    );
    Ok(())
}

/// `talus view DIR`.
pub fn view(dir: &Path, bind: IpAddr, port: u16) -> Result<()> {
    let root = crate::view::viewer_root()?;
    crate::view::serve(dir, bind, port, &root, |addr| {
        println!("talus viewer: http://{addr}/");
        use std::io::Write;
        let _ = std::io::stdout().flush();
    })
}

/// `talus demo`.
pub fn demo(out: &Path, view: bool) -> Result<()> {
    let _ = (out, view);
    Err(Error::Internal("demo is being merged".into()))
}
