//! The `params` subcommand: check, apply or save a vehicle's parameters.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use super::{numbers, runtime};

#[derive(clap::Args)]
pub struct ParamsArgs {
    /// check (compare the file with the vehicle), apply (write it: all or nothing), or save
    /// (download every parameter of the vehicle into the file: a backup before apply).
    pub action: String,
    /// A QGroundControl .params or Mission Planner .parm/.param file.
    pub file: PathBuf,
    /// The vehicle: udpout:HOST:PORT, udpin:HOST:PORT, tcpout:..., serial:PATH:BAUD.
    #[arg(long)]
    pub connect: String,
    /// Seconds to wait for the vehicle's heartbeat.
    #[arg(long, default_value_t = 10.0, value_parser = numbers::timeout_seconds)]
    pub timeout: f64,
    /// MAVLink 2 signing key file (64 hex digits) for a vehicle with signing on.
    #[arg(long)]
    pub signing_key: Option<PathBuf>,
}

/// `infotrack params save FILE`: every parameter of the vehicle into FILE (a backup before
/// `apply`), in the format its extension names.
fn params_save(a: ParamsArgs) -> Result<()> {
    use infotrack::autopilot::{link, params_file, params_sync};
    let format = params_file::ParamFormat::from_path(&a.file).with_context(|| {
        format!(
            "{}: unknown parameter file type (expected .params, .parm or .param)",
            a.file.display()
        )
    })?;
    let key = a
        .signing_key
        .as_deref()
        .map(infotrack::autopilot::signing::SigningKey::load)
        .transpose()?;
    let text = runtime()?.block_on(async {
        let mut lc = link::LinkConfig::new(&a.connect);
        lc.signing_key = key;
        let l = link::VehicleLink::connect(lc).await?;
        l.wait_vehicle(std::time::Duration::from_secs_f64(a.timeout))
            .await?;
        let list = l.param_list(std::time::Duration::from_secs(2)).await;
        if !list.complete {
            bail!(
                "the vehicle sent {} parameters but not all it counts: nothing was saved (a lossy link? try again)",
                list.values.len()
            );
        }
        let address = l.state().address.unwrap_or((1, 1));
        println!("{} parameters of the {} vehicle", list.values.len(), l.flavor());
        Ok::<String, anyhow::Error>(params_sync::render_backup(&list, format, address))
    })?;
    infotrack::report::write_file(&a.file, text.as_bytes())?;
    println!("saved to {}", a.file.display());
    Ok(())
}

pub fn params(a: ParamsArgs) -> Result<()> {
    use infotrack::autopilot::{link, params_file, params_sync};
    let apply = match a.action.as_str() {
        "check" => false,
        "apply" => true,
        "save" => return params_save(a),
        other => bail!("unknown params action `{other}` (check, apply or save)"),
    };
    let file = params_file::read(&a.file)?;
    let key = a
        .signing_key
        .as_deref()
        .map(infotrack::autopilot::signing::SigningKey::load)
        .transpose()?;
    let file_name = a.file.display().to_string();
    let ok = runtime()?.block_on(async move {
        let mut lc = link::LinkConfig::new(&a.connect);
        lc.signing_key = key;
        let l = link::VehicleLink::connect(lc).await?;
        l.wait_vehicle(std::time::Duration::from_secs_f64(a.timeout))
            .await?;
        let rows = if apply {
            params_sync::apply(&l, &file).await
        } else {
            params_sync::check(&l, &file).await
        };
        print!("{}", params_sync::render(&rows));
        for line in params_sync::advice(&rows, l.flavor(), apply) {
            println!("{line}");
        }
        if let (false, Some(why)) = (params_sync::all_ok(&rows), l.signing_diagnosis()) {
            bail!("{file_name}: {why}");
        }
        use params_sync::ParamStatus;
        if let Some(failed) = rows.iter().find(|r| r.status == ParamStatus::Failed) {
            let count = |s: ParamStatus| rows.iter().filter(|r| r.status == s).count();
            bail!(
                "{file_name}: writing {} (line {}) failed midway: {} parameter(s) written before \
                 were set back to their earlier values{}; the rest were not written (see the table)",
                failed.name,
                failed.line,
                count(ParamStatus::RolledBack),
                match count(ParamStatus::RollbackFailed) {
                    0 => String::new(),
                    n => format!(", {n} could NOT be set back and hold the file's values"),
                }
            );
        }
        let untouched = rows.iter().any(|r| r.status == ParamStatus::NotWritten);
        if untouched {
            bail!(
                "{file_name}: nothing was written: the file is applied whole or not at all, and the vehicle lacks some of its parameters or cannot hold their values (see the table)"
            );
        }
        Ok::<bool, anyhow::Error>(params_sync::all_ok(&rows))
    })?;
    if !ok {
        bail!(
            "{}: the vehicle does not match the file (see the table)",
            a.file.display()
        );
    }
    Ok(())
}
