//! Dynamic-size filter steps against hand-written DMatrix and faer baselines (being written).

fn main() {}
