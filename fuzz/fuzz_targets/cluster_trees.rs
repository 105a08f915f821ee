#![no_main]
//! The learned cluster scorer's trees file (STPW tensors read as node tables): never panics on
//! any bytes; what it accepts walks every tree to a leaf and gives probabilities in [0, 1].
use libfuzzer_sys::fuzz_target;
use starc_pipeline::detect::pillars::weights::Weights;
use starc_pipeline::detect::trees::{TreeModel, INPUTS};

fuzz_target!(|data: &[u8]| {
    let Ok(weights) = Weights::parse(data) else { return };
    let Ok(model) = TreeModel::from_weights(&weights) else { return };
    for x in [[0.0f32; INPUTS], [1e30; INPUTS], [-1.0; INPUTS]] {
        let p = model.predict(&x);
        assert!(p.iter().all(|v| (0.0..=1.0).contains(v)), "{p:?}");
    }
});
