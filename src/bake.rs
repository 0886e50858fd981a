//! `ptm bake`.

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: &Args) -> anyhow::Result<serde_json::Value> {
    anyhow::bail!("`ptm bake` is not implemented yet")
}
