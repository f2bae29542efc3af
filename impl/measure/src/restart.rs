//! Starting a measurement's receiver processes again when some never answer its probes: the runs of
//! [`crate::process`] and the sessions of [`crate::bench::payload`]. On the 2-core machine, two of about sixty runs
//! of 16 processes (2026-11-28) had one receiver whose answers never reached the source within the probe window,
//! though the source's writer had matched its reader: an RTPS discovery between two `rustdds` participants that did
//! not complete. Nothing is measured before every receiver has answered, so a start that did not get that far
//! leaves no trace in the figures; the results count the starts.

/// Starts of a measurement's receivers at most; the last one's error is the measurement's.
pub const MAX_STARTS: u32 = 3;

/// Calls `start(1)`, `start(2)`, ... until it returns a value or an error that `retry` does not accept, at most
/// [`MAX_STARTS`] times, and returns the value with the number of starts it took. Before each new start a warning
/// names `what` and the error (`start` stops the receivers it started before it returns its error).
///
/// # Errors
/// The error of the last start: the first one `retry` does not accept, or the [`MAX_STARTS`]th.
pub(crate) fn with_restarts<T>(
    what: &str,
    retry: impl Fn(&anyhow::Error) -> bool,
    mut start: impl FnMut(u32) -> anyhow::Result<T>,
) -> anyhow::Result<(T, u32)> {
    let mut starts = 1;
    loop {
        match start(starts) {
            Ok(value) => return Ok((value, starts)),
            Err(error) if starts < MAX_STARTS && retry(&error) => {
                starts += 1;
                tracing::warn!(
                    "{what}: {error}; stopped its receivers and starting them again (start {starts} of at most \
                     {MAX_STARTS})"
                );
            }
            Err(error) => return Err(error),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("silent receivers")]
    struct Silent;

    fn silent(error: &anyhow::Error) -> bool {
        error.is::<Silent>()
    }

    #[test]
    fn a_start_whose_error_is_retried_starts_again_and_the_starts_are_counted() {
        let mut seen = Vec::new();
        let (value, starts) = with_restarts("a run", silent, |start| {
            seen.push(start);
            if start < 2 { Err(anyhow::Error::from(Silent).context("probing")) } else { Ok("done") }
        })
        .unwrap();
        assert_eq!((value, starts, seen), ("done", 2, vec![1, 2]));
    }

    #[test]
    fn the_last_start_s_error_is_returned_and_other_errors_are_not_retried() {
        let mut calls = 0;
        let error = with_restarts("a run", silent, |_| -> anyhow::Result<()> {
            calls += 1;
            Err(Silent.into())
        })
        .unwrap_err();
        assert_eq!((calls, error.to_string().as_str()), (MAX_STARTS, "silent receivers"));
        calls = 0;
        let error = with_restarts("a run", silent, |_| -> anyhow::Result<()> {
            calls += 1;
            anyhow::bail!("the writing agent did not start")
        })
        .unwrap_err();
        assert_eq!((calls, error.to_string().as_str()), (1, "the writing agent did not start"));
    }
}
