//! The command line's own code, one file per subcommand that needs more than a few lines:
//! binary-only, never imported by the library.

pub mod altitude_bench;
pub mod bench;
pub mod calibrate;
pub mod detect;
pub mod detect_bench;
pub mod numbers;
pub mod run_cmd;
