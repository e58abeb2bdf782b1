//! The `mock-autopilot` subcommand: the mock autopilot on a MAVLink transport until interrupted.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use super::{numbers, runtime};

#[derive(clap::Args)]
pub struct MockArgs {
    /// px4 or ardupilot.
    #[arg(long)]
    pub flavor: String,
    /// Where to listen or connect: udpin:HOST:PORT, tcpin:HOST:PORT, serial:PATH:BAUD, or
    /// `pty` for a pseudo-terminal null modem whose other end is printed for the companion.
    #[arg(long, default_value = "udpin:127.0.0.1:14550")]
    pub listen: String,
    /// Start from the flavour's defaults with this parameter file applied.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Drop this share of messages in both directions, percent.
    #[arg(long, default_value_t = 0.0, value_parser = numbers::percent)]
    pub loss: f64,
    /// One-way latency added to every message, milliseconds.
    #[arg(long, default_value_t = 0.0, value_parser = numbers::millis)]
    pub delay_ms: f64,
    /// Deliver this share of messages twice, percent.
    #[arg(long, default_value_t = 0.0, value_parser = numbers::percent)]
    pub duplicate: f64,
    /// Hold back this share of messages so that later ones overtake them, percent.
    #[arg(long, default_value_t = 0.0, value_parser = numbers::percent)]
    pub reorder: f64,
    /// MAVLink 2 signing key file (64 hex digits): sign everything and refuse unsigned
    /// frames.
    #[arg(long)]
    pub signing_key: Option<PathBuf>,
    /// Seed of the fault draws and of the vehicle's wander.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// How the vehicle answers targets: `sitl` (as the flavour's SITL build measured:
    /// PX4 SIH's slow, wandering loop; ArduCopter's steady one) or `ideal` (exactly).
    #[arg(long, default_value = "sitl", value_parser = ["sitl", "ideal"])]
    pub response: String,
    /// Seconds after start before arming is allowed (the estimator settling).
    #[arg(long, default_value_t = 0.0, value_parser = numbers::seconds)]
    pub estimator_ready_after: f64,
}

pub fn mock_autopilot(a: MockArgs) -> Result<()> {
    use infotrack::mock::{server, MockConfig};
    let flavor: infotrack::autopilot::modes::Flavor =
        a.flavor.parse().map_err(anyhow::Error::msg)?;
    if a.listen != "pty" {
        infotrack::autopilot::link::check_url(&a.listen)
            .map_err(|e| anyhow::anyhow!("--listen `{}`: {e}", a.listen))?;
    }
    for (name, v) in [
        ("--loss", a.loss),
        ("--duplicate", a.duplicate),
        ("--reorder", a.reorder),
    ] {
        if !(0.0..=100.0).contains(&v) {
            bail!("{name} must be a percentage 0-100, got {v}");
        }
    }
    if !(a.delay_ms.is_finite() && (0.0..=60_000.0).contains(&a.delay_ms)) {
        bail!("--delay-ms must be 0-60000, got {}", a.delay_ms);
    }
    let signing_key = a
        .signing_key
        .as_deref()
        .map(infotrack::autopilot::signing::SigningKey::load)
        .transpose()?;
    let mut cfg = MockConfig::new(flavor);
    cfg.estimator_ready_after_s = a.estimator_ready_after;
    cfg.seed = a.seed;
    if a.response == "sitl" {
        cfg.answer_as_sitl();
    }
    if let Some(path) = &a.params {
        let table = infotrack::mock::params::ParamTable::defaults(flavor);
        for p in infotrack::autopilot::params_file::read(path)? {
            if table.by_name(&p.name).is_none() {
                bail!(
                    "{}:{}: the {flavor} mock has no parameter {}",
                    path.display(),
                    p.line,
                    p.name
                );
            }
            cfg.param_overrides.push((p.name, p.value));
        }
    }
    runtime()?.block_on(async move {
        // The null modem must outlive the mock.
        let (_null_modem, listen, companion) = if a.listen == "pty" {
            let nm = infotrack::mock::null_modem::NullModem::new()?;
            let listen = format!("serial:{}:57600", nm.vehicle_path());
            let companion = format!("serial:{}:57600", nm.companion_path());
            (Some(nm), listen, companion)
        } else {
            (None, a.listen.clone(), a.listen.clone())
        };
        let opts = server::ServerOptions {
            faults: server::Faults {
                loss_percent: a.loss,
                delay: std::time::Duration::from_secs_f64(a.delay_ms / 1e3),
                duplicate_percent: a.duplicate,
                reorder_percent: a.reorder,
                seed: a.seed,
            },
            signing_key,
        };
        let _mock = server::spawn_with(&listen, cfg, opts)
            .await
            .with_context(|| format!("cannot open {listen}"))?;
        eprintln!("mock {flavor} autopilot on {listen} (Ctrl-C to stop)");
        if _null_modem.is_some() {
            // The companion's end, on stdout so that scripts can read it.
            println!("{companion}");
        }
        wait_for_signal().await;
        Ok(())
    })
}

async fn wait_for_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        let mut term = signal(SignalKind::terminate()).expect("SIGTERM handler");
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}
