//! `link.gcs_system_ids`: the ground stations a user has (default 255 and
//! MAVSDK's 245); the deprecated one-id `link.gcs_system_id` still read.

use std::path::Path;

use dflat_daemon::config::Config;
use dflat_daemon::tick::source_filter;

fn parse(text: &str) -> Result<Config, String> {
    Config::parse(text, Path::new("t.toml")).map_err(|e| e.to_string())
}

#[test]
fn qgc_and_mavsdk_are_heard_by_default() {
    let c = parse("").unwrap();
    assert_eq!(c.link.ground_station_ids(), vec![255, 245]);
    assert_eq!(source_filter(&c.link).gcs_system_ids, vec![255, 245]);
}

#[test]
fn a_list_is_taken_as_given() {
    let c = parse("[link]\ngcs_system_ids = [255, 7]\n").unwrap();
    assert_eq!(c.link.ground_station_ids(), vec![255, 7]);
}

#[test]
fn the_old_key_is_a_one_element_list() {
    let c = parse("[link]\ngcs_system_id = 200\n").unwrap();
    assert_eq!(c.link.ground_station_ids(), vec![200]);
    assert_eq!(source_filter(&c.link).gcs_system_ids, vec![200]);
}

#[test]
fn bad_ids_are_refused_with_the_field_named() {
    let both = parse("[link]\ngcs_system_id = 200\ngcs_system_ids = [1]\n").unwrap_err();
    assert!(both.contains("`link.gcs_system_id`"), "{both}");
    let empty = parse("[link]\ngcs_system_ids = []\n").unwrap_err();
    assert!(empty.contains("`link.gcs_system_ids`"), "{empty}");
    let zero = parse("[link]\ngcs_system_ids = [255, 0]\n").unwrap_err();
    assert!(zero.contains("`link.gcs_system_ids[1]`"), "{zero}");
    let old_zero = parse("[link]\ngcs_system_id = 0\n").unwrap_err();
    assert!(old_zero.contains("`link.gcs_system_id`"), "{old_zero}");
}
