//! The campaign's network: one Linux network namespace per agent, each joined by a veth pair to a bridge in a
//! hub namespace, so that to RTPS every agent is a separate host on one LAN (multicast discovery included); and the
//! faults, as `nftables` rules inside the agents' namespaces.
//!
//! Every fault is written as input filters on the receiving side, by source address: random loss from some
//! senders (`numgen random mod 100 < N drop`), a one-way cut (only one side filters), a partition (both sides
//! filter), an isolated namespace (nothing in or out on its interface), or held data (nothing arrives on the
//! domain's RTPS user-traffic ports, while discovery on its metatraffic ports passes). A namespace's whole rule set is replaced
//! atomically on every change. Nothing outside the campaign's own namespaces is touched: the host's namespace keeps
//! its interfaces, routes and rules, and [`Network`]'s `Drop` deletes the namespaces (their veth pairs go with
//! them); a campaign that was killed before it could do so has its namespaces removed by the next one.

use std::collections::BTreeSet;
use std::io::Write;
use std::net::Ipv4Addr;
use std::path::Path;
use std::process::{Command, Stdio};

use anyhow::{Context, Result, bail};

/// What an agent's namespace filters on input.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Filter {
    /// Drop this percentage of what comes from these agents (100: all of it).
    pub drop_from: Vec<(BTreeSet<usize>, u8)>,
    /// Nothing in or out on the namespace's interface.
    pub isolated: bool,
    /// Drop what arrives on this DDS domain's user-traffic ports ([`user_traffic_ports`]): the agents' messages
    /// do not reach this one, while RTPS discovery (the metatraffic ports) goes on, so that it has found its peers
    /// once the filter is lifted.
    pub hold_data_of_domain: Option<u16>,
}

/// The UDP ports of a DDS domain's user traffic, by the RTPS default port mapping (RTPS 2.5, 9.6.1.1: `PB` 7400,
/// `DG` 250, `PG` 2, `d2` 1, `d3` 11): the multicast port and the unicast port of every participant id rustdds
/// tries (0 to 119). The metatraffic ports (`d0` 0, `d1` 10: SPDP and SEDP) are not among them. Ports past 65,535
/// (domains above 232, which RTPS cannot use either) are left out.
pub fn user_traffic_ports(domain: u16) -> Vec<u16> {
    let base = 7400 + 250 * u32::from(domain);
    std::iter::once(base + 1)
        .chain((0..120).map(|participant| base + 11 + 2 * participant))
        .filter_map(|port| u16::try_from(port).ok())
        .collect()
}

/// The campaign's namespaces.
#[derive(Debug)]
pub struct Network {
    tag: String,
    created: Vec<String>,
    /// Every agent slot in the namespace of slot 0 (`cortex chaos --same-host`).
    same_host: bool,
}

/// Checks that this process can build the network: root, `ip` (iproute2) and `nft` (nftables).
///
/// # Errors
/// Says which is missing and which Debian package provides it (`scripts/chaos-deps.sh` installs both).
pub fn preflight() -> Result<()> {
    let uid = Command::new("id").arg("-u").output().context("running `id -u`")?;
    if String::from_utf8_lossy(&uid.stdout).trim() != "0" {
        bail!("cortex chaos must run as root: it creates network namespaces and nftables rules");
    }
    for (program, package) in [("ip", "iproute2"), ("nft", "nftables")] {
        let found = Command::new("sh").args(["-c", &format!("command -v {program}")]).output();
        if !found.is_ok_and(|o| o.status.success()) {
            bail!("`{program}` not found on PATH (Debian package {package}; scripts/chaos-deps.sh installs it)");
        }
    }
    Ok(())
}

fn run(args: &[&str]) -> Result<()> {
    let output = Command::new(args[0]).args(&args[1..]).output().with_context(|| format!("running {args:?}"))?;
    if !output.status.success() {
        bail!("{} failed: {}", args.join(" "), String::from_utf8_lossy(&output.stderr).trim());
    }
    Ok(())
}

impl Network {
    /// Creates the hub and `agents` agent namespaces, named after `tag` (e.g. `cx1234`); with `same_host`, one
    /// agent namespace that every slot shares.
    ///
    /// # Errors
    /// A command failed (its standard error is quoted); what was created is deleted again.
    pub fn create(tag: &str, agents: usize, same_host: bool) -> Result<Network> {
        remove_stale();
        let mut network = Network { tag: tag.to_owned(), created: Vec::new(), same_host };
        let agents = if same_host { 1 } else { agents };
        let hub = network.hub();
        network.add_namespace(&hub)?;
        run(&["ip", "-n", &hub, "link", "set", "lo", "up"])?;
        run(&["ip", "-n", &hub, "link", "add", "br0", "type", "bridge", "mcast_snooping", "0"])?;
        run(&["ip", "-n", &hub, "link", "set", "br0", "up"])?;
        for agent in 0..agents {
            let ns = network.namespace(agent);
            network.add_namespace(&ns)?;
            let port = format!("h{agent}");
            run(&["ip", "-n", &hub, "link", "add", &port, "type", "veth", "peer", "name", "eth0", "netns", &ns])?;
            run(&["ip", "-n", &hub, "link", "set", &port, "master", "br0", "up"])?;
            let address = format!("{}/24", Self::address(agent));
            run(&["ip", "-n", &ns, "link", "set", "lo", "up"])?;
            run(&["ip", "-n", &ns, "addr", "add", &address, "dev", "eth0"])?;
            run(&["ip", "-n", &ns, "link", "set", "eth0", "up"])?;
            run(&["ip", "-n", &ns, "route", "add", "224.0.0.0/4", "dev", "eth0"])?;
            network.set_filter(agent, &Filter::default())?;
        }
        Ok(network)
    }

    fn add_namespace(&mut self, name: &str) -> Result<()> {
        // A namespace left by a campaign that was killed is replaced.
        let _ = run(&["ip", "netns", "del", name]);
        run(&["ip", "netns", "add", name])?;
        self.created.push(name.to_owned());
        Ok(())
    }

    fn hub(&self) -> String {
        format!("{}-hub", self.tag)
    }

    /// The namespace of agent slot `agent` (slot 0's for every slot with `same_host`).
    pub fn namespace(&self, agent: usize) -> String {
        let agent = if self.same_host { 0 } else { agent };
        format!("{}-a{agent}", self.tag)
    }

    /// The address of agent slot `agent` (198.19.0.0/24, part of the benchmarking range).
    pub fn address(agent: usize) -> Ipv4Addr {
        Ipv4Addr::new(198, 19, 0, 10 + agent as u8)
    }

    /// Replaces the input filter of agent slot `agent`'s namespace.
    ///
    /// # Errors
    /// `nft` refused the rule set (quoted).
    pub fn set_filter(&self, agent: usize, filter: &Filter) -> Result<()> {
        let ruleset = ruleset(filter);
        let mut child = Command::new("ip")
            .args(["netns", "exec", &self.namespace(agent), "nft", "-f", "-"])
            .stdin(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .context("running nft")?;
        child.stdin.take().context("nft's standard input")?.write_all(ruleset.as_bytes())?;
        let output = child.wait_with_output()?;
        if !output.status.success() {
            bail!("nft refused the rules of agent {agent}: {}\n{ruleset}", String::from_utf8_lossy(&output.stderr));
        }
        Ok(())
    }
}

/// Deletes the namespaces of campaigns whose process is gone (killed before it could clean up): names
/// `cx<PID>-...` with no process `PID`.
fn remove_stale() {
    let Ok(list) = Command::new("ip").args(["netns", "list"]).output() else { return };
    for line in String::from_utf8_lossy(&list.stdout).lines() {
        let name = line.split_whitespace().next().unwrap_or("");
        let Some(pid) = stale_pid(name) else { continue };
        if !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = run(&["ip", "netns", "del", name]);
        }
    }
}

/// The campaign process id in a namespace name `cx<PID>-...`.
fn stale_pid(name: &str) -> Option<u32> {
    name.strip_prefix("cx")?.split_once('-')?.0.parse().ok()
}

/// The `nft -f` input that replaces the `inet chaos` table with `filter`.
pub fn ruleset(filter: &Filter) -> String {
    let mut input = String::new();
    let mut output = String::new();
    if filter.isolated {
        input.push_str("    iifname \"eth0\" drop\n");
        output.push_str("    oifname \"eth0\" drop\n");
    }
    for (from, percent) in &filter.drop_from {
        if from.is_empty() || *percent == 0 {
            continue;
        }
        let set: Vec<String> = from.iter().map(|a| Network::address(*a).to_string()).collect();
        let random = if *percent >= 100 { String::new() } else { format!("numgen random mod 100 < {percent} ") };
        input.push_str(&format!("    ip saddr {{ {} }} {random}drop\n", set.join(", ")));
    }
    if let Some(domain) = filter.hold_data_of_domain {
        let ports: Vec<String> = user_traffic_ports(domain).iter().map(u16::to_string).collect();
        input.push_str(&format!("    iifname \"eth0\" udp dport {{ {} }} drop\n", ports.join(", ")));
    }
    format!(
        "table inet chaos\ndelete table inet chaos\ntable inet chaos {{\n  chain input {{\n    type filter hook input \
         priority 0; policy accept;\n{input}  }}\n  chain output {{\n    type filter hook output priority 0; policy \
         accept;\n{output}  }}\n}}\n"
    )
}

impl Drop for Network {
    fn drop(&mut self) {
        for name in self.created.iter().rev() {
            let _ = run(&["ip", "netns", "del", name]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rules_drop_by_source_at_a_rate_or_isolate() {
        let open = ruleset(&Filter::default());
        assert!(!open.contains("drop"), "{open}");
        let filter = Filter {
            drop_from: vec![([1, 2].into(), 30), ([3].into(), 100)],
            isolated: false,
            hold_data_of_domain: None,
        };
        let rules = ruleset(&filter);
        assert!(rules.contains("ip saddr { 198.19.0.11, 198.19.0.12 } numgen random mod 100 < 30 drop"), "{rules}");
        assert!(rules.contains("ip saddr { 198.19.0.13 } drop"), "{rules}");
        let isolated = ruleset(&Filter { isolated: true, ..Filter::default() });
        assert!(isolated.contains("iifname \"eth0\" drop") && isolated.contains("oifname \"eth0\" drop"));
        let held = ruleset(&Filter { hold_data_of_domain: Some(47), ..Filter::default() });
        assert!(held.contains("iifname \"eth0\" udp dport { 19151, 19161, 19163, "), "{held}");
        assert!(held.contains(", 19399 } drop"), "{held}");
        // Discovery passes: SPDP multicast and the first participants' metatraffic unicast ports.
        assert!(!held.contains("19150") && !held.contains("19160,") && !held.contains("19162"), "{held}");
        assert_eq!(stale_pid("cx1234-a0"), Some(1234));
        assert_eq!(stale_pid("cx1234-hub"), Some(1234));
        assert_eq!(stale_pid("mynet"), None);
        assert_eq!(stale_pid("cxfoo-a1"), None);
    }
}
