//! One module per `cortex` subcommand; each has an `Args` type for clap and a `run` function that returns an
//! `anyhow::Result`. Later subcommands (`check`, `agent`, `bench`, `replay`, `report`, `inspect`) go beside
//! `graph`.

pub mod agent;
pub mod bench;
pub mod bridge;
pub mod chaos;
pub mod check;
pub mod datasets;
pub mod graph;
pub mod inspect;
pub mod receiver;
pub mod replay;
pub mod report;
pub mod security;

/// Makes `$arg`, a tuple struct around one value of a type with `name()` and `summary()`, a clap value enum over the
/// values `$all` yields, each named by `name()` with `summary()` as its help, and shown by its name.
macro_rules! value_enum_by_name {
    ($arg:ident, $all:expr) => {
        impl clap::ValueEnum for $arg {
            fn value_variants<'a>() -> &'a [Self] {
                static ALL: std::sync::LazyLock<Vec<$arg>> =
                    std::sync::LazyLock::new(|| $all.into_iter().map($arg).collect());
                &ALL
            }

            fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
                Some(clap::builder::PossibleValue::new(self.0.name()).help(self.0.summary()))
            }
        }

        impl std::fmt::Display for $arg {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.0.name())
            }
        }
    };
}
pub(crate) use value_enum_by_name;
