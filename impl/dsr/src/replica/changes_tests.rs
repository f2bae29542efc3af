//! The attribute-write look ([`Replica::touched_by_attrs`]) against the general one ([`Replica::touched_by_any`]):
//! on random histories of three replicas with partial delivery (concurrent writes, removals, deletions, attributes
//! arriving before their node), every delivered delta gives the same change events either way.

use proptest::prelude::*;

use super::install_tests::{run_with, step};
use super::*;
use crate::delta::Delta;

/// The change events of joining `delta` into `replica`, looking at `touched` before and after.
fn events(replica: &Replica, delta: &Delta, touched: &changes::Touched) -> Vec<ChangeEvent> {
    let mut joined = replica.clone();
    joined.set_change_tracking(false);
    let before = replica.look(touched);
    joined.join(delta);
    let after = joined.look(touched);
    joined.set_change_tracking(true);
    joined.record_changes(touched, &before, &after, delta.origin.map(|o| o.replica));
    joined.drain_changes()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn an_attribute_write_changes_what_the_general_look_says(steps in prop::collection::vec(step(), 1..60)) {
        let mut failure = None;
        run_with(&steps, |replica, delta| {
            let Some(attrs_only) = replica.touched_by_attrs(delta) else { return };
            let fast = events(replica, delta, &attrs_only);
            let general = events(replica, delta, &replica.touched_by_any(delta));
            if fast != general && failure.is_none() {
                failure = Some(format!("attribute look {fast:?}, general look {general:?}, delta {delta:?}"));
            }
        });
        prop_assert!(failure.is_none(), "{}", failure.unwrap_or_default());
    }
}

#[test]
fn an_attribute_write_takes_the_short_look_and_an_insert_or_delete_does_not() {
    let mut writer = Replica::new(ReplicaId(1));
    let (id, inserted) = writer.insert_node(1, NewNode::new("object", "cup")).unwrap();
    let written = writer.set_attr(2, id, crate::attrs::POS_X, 1.0f32).unwrap();
    let removed = writer.remove_attr(3, id, "pos_x").unwrap();
    let deleted = writer.delete_node(4, id).unwrap();
    let mut reader = Replica::new(ReplicaId(2));
    reader.apply(&inserted).unwrap();
    let touched = reader.touched_by_attrs(&written).expect("an attribute write");
    assert_eq!(touched.attrs.len(), 1);
    assert!(touched.edges.is_empty());
    assert!(reader.touched_by_attrs(&removed).is_some(), "an attribute removal too");
    assert!(reader.touched_by_attrs(&inserted).is_none(), "an insert has a core");
    assert!(reader.touched_by_attrs(&deleted).is_none(), "a deletion has a tombstone");
}

#[test]
fn an_attribute_delta_whose_context_takes_a_core_value_gets_the_general_look() {
    let mut writer = Replica::new(ReplicaId(1));
    let (id, inserted) = writer.insert_node(1, NewNode::new("object", "cup")).unwrap();
    let mut written = (*writer.set_attr(2, id, crate::attrs::POS_X, 1.0f32).unwrap()).clone();
    let mut reader = Replica::new(ReplicaId(2));
    reader.apply(&inserted).unwrap();
    // A foreign writer's delta that also covers the node's core: joined, the node goes.
    for dot in reader.store.nodes[&id].core.dots() {
        written.ctx.insert(dot);
    }
    assert!(reader.touched_by_attrs(&written).is_none());
    let general = events(&reader, &written, &reader.touched_by_any(&written));
    assert!(general.iter().any(|e| e.change == Change::NodeDeleted { id }), "{general:?}");
}
