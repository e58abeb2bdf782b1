//! Connection URLs checked before they reach the transport.

use thiserror::Error;

/// A MAVLink connection URL that is not one, and why.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{0}")]
pub struct BadUrl(pub String);

/// Checks a connection URL before handing it to the transport, for a clear error.
pub fn check_url(url: &str) -> Result<(), BadUrl> {
    url_reason(url)
}

fn url_reason(url: &str) -> Result<(), BadUrl> {
    let (scheme, rest) = url.split_once(':').ok_or_else(|| {
        BadUrl(
            "expected SCHEME:ADDRESS, e.g. udpin:0.0.0.0:14540 or serial:/dev/ttyAMA0:921600"
                .to_string(),
        )
    })?;
    if scheme == "file" {
        // A telemetry log read as a connection (sends go nowhere), as rust-mavlink opens it.
        if rest.is_empty() {
            return Err(BadUrl("missing file path".into()));
        }
        return Ok(());
    }
    let (a, b) = rest.rsplit_once(':').ok_or_else(|| {
        BadUrl(format!(
            "`{rest}` needs a final `:PORT` (or `:BAUD` for serial)"
        ))
    })?;
    match scheme {
        "udpin" | "udpout" | "tcpin" | "tcpout" | "udpbcast" => {
            b.parse::<u16>()
                .map_err(|_| BadUrl(format!("port `{b}` is not a number 0-65535")))?;
            if a.is_empty() {
                return Err(BadUrl("missing host".into()));
            }
        }
        "serial" => {
            b.parse::<u32>()
                .map_err(|_| BadUrl(format!("baud rate `{b}` is not a number")))?;
            if a.is_empty() {
                return Err(BadUrl("missing serial device path".into()));
            }
        }
        other => {
            return Err(BadUrl(format!(
                "unknown scheme `{other}` (udpin, udpout, tcpin, tcpout, serial, file)"
            )))
        }
    }
    Ok(())
}
