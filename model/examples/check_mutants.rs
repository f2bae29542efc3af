//! Runs the mutant check and prints what killed each mutant:
//! `cargo run --release -p model --features mutants --example check_mutants`.

fn main() {
    for result in model::mutants::check_all_mutants(false) {
        println!(
            "{:<40} {} by {:?} ({} states, {:.2} s)",
            result.mutant,
            if result.killed { "killed" } else { "SURVIVED" },
            result.killed_by,
            result.report.unique_states,
            result.report.seconds
        );
        if let Some(path) = &result.counterexample {
            for (i, action) in path.actions.iter().enumerate() {
                println!("      {:>2}. {action}", i + 1);
            }
        }
    }
}
