//! scratch
use model::scheduler::{SchedulerModel, SchedulerModelConfig};
use stateright::Model;
use std::collections::HashSet;
#[test]
fn dep_miss_without_overrun() {
    let c = SchedulerModelConfig { max_overruns: 0, horizon_ns: 60, max_list_changes: 3, check_determinism: false, ..SchedulerModelConfig::default() };
    let m = SchedulerModel::new(c).unwrap();
    let mut seen = HashSet::new();
    let mut stack = vec![(m.initial_state(), Vec::<String>::new())];
    let mut found = 0;
    while let Some((s, path)) = stack.pop() {
        if !seen.insert(s.clone()) { continue; }
        if s.last_events().iter().any(|e| matches!(e, bica::trace::TraceEvent::Miss(_))) && found < 2 {
            found += 1;
            eprintln!("{}\n{:?}", path.join("\n"), s);
        }
        let mut acts = Vec::new();
        m.actions(&s, &mut acts);
        for a in acts { if let Some(n) = m.apply(&s, a) { let mut p = path.clone(); p.push(m.format_action(&a)); stack.push((n, p)); } }
    }
    eprintln!("states {} found {found}", seen.len());
}
