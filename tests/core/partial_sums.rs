//! The bytes of a training shard's partial sums: exact round trips (every
//! f64 bit, signed zeros, NaN payloads), and truncated or corrupt bytes
//! refused with an error, never a panic.

use l3::l3::learn::{
    Gram, GramPartial, LearnError, Node, SurveyPartial, SurveyShape, cover, merge_partials,
    merge_surveys,
};
use proptest::prelude::*;

const NF: usize = 4;

fn gram_partial(n_batches: usize, start: usize, end: usize, values: &[f64]) -> GramPartial {
    let n_classes = 5;
    let mut v = values.iter().copied().cycle();
    let nodes: Vec<(Node, _)> = cover(start..end, n_batches)
        .into_iter()
        .enumerate()
        .map(|(i, node)| {
            let sums = (0..n_classes)
                .map(|c| {
                    ((c + i) % 3 != 0).then(|| {
                        let mut g = Gram::new(NF);
                        for _ in 0..(c + 1) * 7 {
                            let x: Vec<f32> =
                                (0..NF).map(|_| v.next().unwrap_or(0.0) as f32).collect();
                            g.push(&x, [1.0, -0.0, v.next().unwrap_or(0.0) as f32]);
                        }
                        g.flush();
                        Box::new(g)
                    })
                })
                .collect();
            (node, sums)
        })
        .collect();
    GramPartial {
        run_key: "run".into(),
        n_batches,
        batches: start..end,
        n_features: NF,
        n_classes,
        classes_digest: "digest".into(),
        nodes,
    }
}

fn sums_bits(p: &GramPartial) -> Vec<(Node, usize, u64, Vec<u64>)> {
    let mut out = Vec::new();
    for (node, sums) in &p.nodes {
        for (c, g) in sums.iter().enumerate() {
            if let Some(g) = g {
                let (m, n) = g.flushed_sums().unwrap();
                out.push((*node, c, n, m.iter().map(|x| x.to_bits()).collect()));
            }
        }
    }
    out
}

fn survey_partial(start: usize, end: usize, seed: u64) -> SurveyPartial {
    let shape = SurveyShape {
        n_positions: 2,
        n_levels: 3,
        n_masks: 4,
        bins: 16,
    };
    let cells = shape.n_cells();
    let hist = (0..cells)
        .map(|k| {
            if (k as u64).wrapping_add(seed).is_multiple_of(3) {
                (0..16).map(|b| seed.wrapping_mul(b + 1) >> 3).collect()
            } else {
                Vec::new()
            }
        })
        .collect();
    SurveyPartial {
        run_key: "run".into(),
        n_batches: 12,
        batches: start..end,
        shape,
        hist,
        count: (0..cells as u64).map(|k| k.wrapping_mul(seed)).collect(),
    }
}

/// Every truncation and every byte flipped is refused.
fn assert_refuses_damage<T: std::fmt::Debug>(
    bytes: &[u8],
    read: impl Fn(&[u8]) -> Result<T, LearnError>,
) {
    assert!(read(bytes).is_ok());
    for len in 0..bytes.len() {
        assert!(read(&bytes[..len]).is_err(), "truncated to {len}");
    }
    for i in 0..bytes.len() {
        let mut b = bytes.to_vec();
        b[i] ^= 0xff;
        assert!(
            matches!(read(&b), Err(LearnError::PartialSums(_))),
            "byte {i} flipped"
        );
    }
}

#[test]
fn damaged_partials_are_refused() {
    let p = gram_partial(6, 1, 5, &[0.5, -1.25, 3.0, 1e-7]);
    assert_refuses_damage(&p.to_bytes().unwrap(), GramPartial::from_bytes);
    let s = survey_partial(4, 9, 7);
    assert_refuses_damage(&s.to_bytes().unwrap(), SurveyPartial::from_bytes);
    // one stage's bytes are not the other's
    assert!(GramPartial::from_bytes(&s.to_bytes().unwrap()).is_err());
    assert!(SurveyPartial::from_bytes(&p.to_bytes().unwrap()).is_err());
}

#[test]
fn survey_shards_merge_to_the_sum_of_their_counts() {
    let parts = [survey_partial(4, 12, 5), survey_partial(0, 4, 2)];
    let all = merge_surveys(&parts).unwrap();
    assert_eq!(all.batches, 0..12);
    for k in 0..all.count.len() {
        assert_eq!(all.count[k], parts[0].count[k] + parts[1].count[k]);
    }
    assert!(merge_surveys(&parts[..1]).is_err(), "batches 0..4 missing");
    assert!(merge_surveys(&[parts[0].clone(), parts[0].clone()]).is_err());
    let mut short = parts[1].clone();
    short.hist.pop();
    assert!(merge_surveys(&[parts[0].clone(), short]).is_err());
}

#[test]
fn merge_refuses_nodes_outside_their_shard() {
    let classes = l3::l3::learn::Classes {
        sat_cases: vec![0],
        thresholds: vec![0.0; 3],
    };
    let mut a = gram_partial(6, 0, 3, &[1.0]);
    let b = gram_partial(6, 3, 6, &[2.0]);
    a.classes_digest = classes.digest();
    let mut b2 = b.clone();
    b2.classes_digest = classes.digest();
    assert!(merge_partials(&classes, vec![a.clone(), b2.clone()]).is_ok());
    let mut stray = a.clone();
    stray.nodes[0].0 = Node { lo: 4, log2: 0 };
    assert!(merge_partials(&classes, vec![stray, b2.clone()]).is_err());
    let mut odd = a.clone();
    odd.nodes[0].1[1] = Some(Box::new(Gram::new(NF + 1)));
    assert!(merge_partials(&classes, vec![odd, b2]).is_err());
    // parts accumulated for other classes
    assert!(merge_partials(&classes, vec![a, b]).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn gram_partials_round_trip_bit_for_bit(
        values in prop::collection::vec(
            prop_oneof![
                any::<f64>(),
                Just(-0.0),
                Just(f64::NAN),
                Just(f64::INFINITY),
                -1e3f64..1e3,
            ],
            1..64,
        ),
        n_batches in 1usize..40,
        a in 0usize..40,
        b in 0usize..40,
    ) {
        let (start, end) = (a.min(b) % n_batches, (a.max(b) % n_batches) + 1);
        prop_assume!(start < end);
        let p = gram_partial(n_batches, start, end, &values);
        let bytes = p.to_bytes().unwrap();
        let q = GramPartial::from_bytes(&bytes).unwrap();
        prop_assert_eq!(sums_bits(&p), sums_bits(&q));
        prop_assert_eq!(q.to_bytes().unwrap(), bytes);
        prop_assert_eq!((q.batches, q.n_batches), (start..end, n_batches));
    }

    #[test]
    fn survey_partials_round_trip(seed in any::<u64>(), start in 0usize..11, len in 1usize..12) {
        let end = (start + len).min(12);
        let s = survey_partial(start, end, seed);
        let bytes = s.to_bytes().unwrap();
        let t = SurveyPartial::from_bytes(&bytes).unwrap();
        prop_assert_eq!(&t, &s);
        prop_assert_eq!(t.to_bytes().unwrap(), bytes);
    }
}
