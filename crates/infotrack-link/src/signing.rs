//! MAVLink 2 message signing keys, read from a key file.
//!
//! The file holds the 32-byte secret as 64 hexadecimal digits on one line (`#` comments and
//! blank lines allowed), the form in which ground stations display a key. The same file is
//! given to the vehicle (or the mock) and to infotrack.

use std::path::Path;

use thiserror::Error;

/// Why a key file was refused.
#[derive(Debug, Error)]
pub enum SigningKeyError {
    /// The file could not be read.
    #[error("signing key file {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// The content is not one line of 64 hex digits.
    #[error("signing key file {path}, line {line}: {message}")]
    Format {
        /// The file.
        path: String,
        /// 1-based line (0: the file as a whole).
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// A 32-byte MAVLink 2 signing secret.
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey(pub [u8; 32]);

impl std::fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never print the secret into logs.
        f.write_str("SigningKey(..)")
    }
}

impl SigningKey {
    /// Reads a key file.
    pub fn load(path: &Path) -> Result<Self, SigningKeyError> {
        let text = std::fs::read_to_string(path).map_err(|source| SigningKeyError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses the content of a key file named `origin` (for messages).
    pub fn parse(text: &str, origin: &str) -> Result<Self, SigningKeyError> {
        let err = |line: usize, message: String| SigningKeyError::Format {
            path: origin.to_string(),
            line,
            message,
        };
        let mut key = None;
        for (i, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            if key.is_some() {
                return Err(err(
                    i + 1,
                    "a second key; the file holds exactly one".into(),
                ));
            }
            if !line.is_ascii() || line.len() != 64 {
                return Err(err(
                    i + 1,
                    format!(
                        "expected 64 hex digits (32 bytes), found {}",
                        line.chars().count()
                    ),
                ));
            }
            let mut k = [0u8; 32];
            for (j, byte) in k.iter_mut().enumerate() {
                let pair = &line[2 * j..2 * j + 2];
                *byte = u8::from_str_radix(pair, 16).map_err(|_| {
                    err(
                        i + 1,
                        format!("`{pair}` at column {} is not hexadecimal", 2 * j + 1),
                    )
                })?;
            }
            key = Some(k);
        }
        key.map(SigningKey)
            .ok_or_else(|| err(0, "no key (64 hex digits) in the file".into()))
    }

    /// The crate's signing configuration: sign what we send on `link_id`, and accept only
    /// frames signed with this key.
    pub fn config(&self, link_id: u8) -> mavlink::SigningConfig {
        mavlink::SigningConfig::new(self.0, link_id, true, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_hex_with_comments() {
        let text =
            "# lab key\n\n000102030405060708090a0b0c0d0e0f101112131415161718191A1B1C1D1E1F # x\n";
        let k = SigningKey::parse(text, "k").unwrap();
        assert_eq!(k.0[0], 0);
        assert_eq!(k.0[26], 0x1a);
        assert_eq!(k.0[31], 0x1f);
        assert_eq!(format!("{k:?}"), "SigningKey(..)");
    }

    #[test]
    fn bad_keys_name_the_line() {
        let e = SigningKey::parse("# c\nabc\n", "key.txt")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("key.txt, line 2") && e.contains("found 3"),
            "{e}"
        );
        let bad = format!("{}zz", "0".repeat(62));
        let e = SigningKey::parse(&bad, "k").unwrap_err().to_string();
        assert!(
            e.contains("line 1") && e.contains("`zz` at column 63"),
            "{e}"
        );
        let two = format!("{0}\n{0}\n", "0".repeat(64));
        assert!(SigningKey::parse(&two, "k")
            .unwrap_err()
            .to_string()
            .contains("line 2"));
        assert!(SigningKey::parse("# only\n", "k")
            .unwrap_err()
            .to_string()
            .contains("no key"));
        let missing = SigningKey::load(Path::new("/nonexistent/key")).unwrap_err();
        assert!(missing.to_string().contains("/nonexistent/key"));
    }
}
