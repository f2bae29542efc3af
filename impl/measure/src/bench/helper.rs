//! The helper processes of the benchmarks: the program given to a benchmark (the `cortex` binary) started with one
//! of the command lines here, which its hidden `bench` subcommands implement by calling the helper bodies
//! ([`super::rtt::echo`], [`super::join::child`], [`super::fanout::reader`], the receivers of [`super::payload`]). A helper is killed when dropped.

use std::path::Path;
use std::process::{Child, ChildStdout, Command, Stdio};

use anyhow::Context as _;
use transport::rtps::{Multicast, UpdateDelivery};

use super::multicast_name;

/// A helper process, killed when dropped.
#[derive(Debug)]
pub struct Helper(Child);

impl Helper {
    /// Starts `program` with `args`, its standard output piped to this process.
    ///
    /// # Errors
    /// The program cannot be started.
    pub fn spawn(program: &Path, args: &[String]) -> anyhow::Result<Helper> {
        let child = Command::new(program)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .with_context(|| format!("starting a helper process ({})", program.display()))?;
        Ok(Helper(child))
    }

    /// The helper's process id.
    pub fn pid(&self) -> u32 {
        self.0.id()
    }

    /// Waits up to `timeout` for the helper to exit by itself; says whether it did (if not, dropping it kills it).
    pub fn exited_within(&mut self, timeout: std::time::Duration) -> bool {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            match self.0.try_wait() {
                Ok(Some(_)) => return true,
                Ok(None) if std::time::Instant::now() < deadline => {
                    std::thread::sleep(std::time::Duration::from_millis(10));
                }
                Ok(None) | Err(_) => return false,
            }
        }
    }

    /// The helper's standard output (once).
    pub fn take_stdout(&mut self) -> Option<ChildStdout> {
        self.0.stdout.take()
    }
}

impl Drop for Helper {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `bench echo`: echoes pings, raw samples or through an agent.
/// With `security`, the helper joins with DDS Security's credentials in that directory; with `shm`, over same-host
/// shared memory instead of RTPS.
pub fn echo_args(
    domain: u16,
    prefix: &str,
    raw: bool,
    multicast: Multicast,
    updates: UpdateDelivery,
    security: Option<&Path>,
    shm: bool,
) -> Vec<String> {
    let mut args = vec!["bench".into(), "echo".into(), "--domain".into(), domain.to_string(), "--prefix".into()];
    args.push(prefix.into());
    if raw {
        args.push("--raw".into());
    }
    args.extend(["--multicast".into(), multicast_name(multicast).into(), "--updates".into(), updates.name().into()]);
    args.extend(security_args(security));
    if shm {
        args.push("--shm".into());
    }
    args
}

fn security_args(security: Option<&Path>) -> Vec<String> {
    security.map(|dir| vec!["--security".to_owned(), dir.display().to_string()]).unwrap_or_default()
}

/// `bench join-child`: joins (with DDS Security's credentials in `security`, if given), then prints its
/// [`super::join::JoinChildReport`] as one JSON line.
pub fn join_child_args(domain: u16, prefix: &str, nodes: u32, security: Option<&Path>) -> Vec<String> {
    let mut args: Vec<String> =
        ["bench", "join-child", "--domain", &domain.to_string(), "--prefix", prefix, "--nodes", &nodes.to_string()]
            .map(String::from)
            .to_vec();
    args.extend(security_args(security));
    args
}

/// `bench fanout-reader`: counts the fan-out's samples and reports the count.
pub fn fanout_reader_args(domain: u16, prefix: &str, multicast: Multicast) -> Vec<String> {
    ["bench", "fanout-reader", "--domain", &domain.to_string(), "--prefix", prefix, "--multicast"]
        .map(String::from)
        .into_iter()
        .chain([multicast_name(multicast).to_owned()])
        .collect()
}

/// `bench payload-receiver`: receiver `index` of a payload path (`iceoryx2`, or agents over a link by its name)
/// on services or topics of `prefix`; see [`super::payload`].
pub fn payload_receiver_args(path: &str, domain: u16, prefix: &str, index: u32) -> Vec<String> {
    ["bench", "payload-receiver", "--path", path, "--domain", &domain.to_string(), "--prefix", prefix, "--index"]
        .map(String::from)
        .into_iter()
        .chain([index.to_string()])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn helper_command_lines_name_every_setting() {
        let echo = echo_args(3, "p", true, Multicast::Off, UpdateDelivery::Reliable, None, false);
        assert_eq!(echo.join(" "), "bench echo --domain 3 --prefix p --raw --multicast off --updates reliable");
        let shm = echo_args(3, "p", false, Multicast::Off, UpdateDelivery::Reliable, None, true);
        assert_eq!(shm.join(" "), "bench echo --domain 3 --prefix p --multicast off --updates reliable --shm");
        assert_eq!(join_child_args(1, "j", 10, None).join(" "), "bench join-child --domain 1 --prefix j --nodes 10");
        assert_eq!(
            join_child_args(1, "j", 10, Some(Path::new("/k/b"))).join(" "),
            "bench join-child --domain 1 --prefix j --nodes 10 --security /k/b"
        );
        assert_eq!(
            fanout_reader_args(2, "f", Multicast::On).join(" "),
            "bench fanout-reader --domain 2 --prefix f --multicast on"
        );
        assert_eq!(
            payload_receiver_args("shm", 4, "p", 7).join(" "),
            "bench payload-receiver --path shm --domain 4 --prefix p --index 7"
        );
    }
}
