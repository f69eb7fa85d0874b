//! Tests only: one command's arguments parsed as `bitt COMMAND ...` parses them.

use std::ffi::OsString;

/// The arguments `A` of one command, parsed from a command line whose first word stands for
/// the program (`["bitt", "--preset", "tiny", ...]`).
#[derive(Debug)]
pub(crate) struct Parsed<A> {
    /// The parsed arguments.
    pub(crate) args: A,
}

impl<A: clap::Args + clap::FromArgMatches> Parsed<A> {
    /// Parses `argv` as clap would for the subcommand whose arguments are `A`.
    pub(crate) fn try_parse_from<I, T>(argv: I) -> Result<Self, clap::Error>
    where
        I: IntoIterator<Item = T>,
        T: Into<OsString> + Clone,
    {
        let matches = A::augment_args(clap::Command::new("bitt")).try_get_matches_from(argv)?;
        Ok(Parsed {
            args: A::from_arg_matches(&matches)?,
        })
    }
}
