//! `ptm preview`.

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: &Args) -> anyhow::Result<serde_json::Value> {
    anyhow::bail!("`ptm preview` is not implemented yet")
}
