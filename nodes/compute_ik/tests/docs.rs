//! docs/parameters.md's compute_ik table is what `compute_ik::spec()` declares.

#[test]
fn the_parameters_page_lists_what_the_node_declares() {
    if let Err(why) = ros_plumbing::docs::check_node_parameters(&compute_ik::spec()) {
        panic!("{why}");
    }
}
