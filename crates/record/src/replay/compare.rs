//! `--compare`: the unfiltered tip force of the observable estimates
//! against a reference channel, paired by stamp (MODEL.md 6's absolute
//! relative error, RMS and maximum per axis).

use super::options::ReplayError;
use super::report::{AxisError, Comparison};

/// The newest reference at or before `t` (`refs` in stamp order).
pub(super) fn reference_at(refs: &[(u64, [f64; 3])], t: u64) -> Option<[f64; 3]> {
    let i = refs.partition_point(|(s, _)| *s <= t);
    refs.get(i.checked_sub(1)?).map(|(_, f)| *f)
}

/// The comparison of the `estimates` (stamp, tip force N; `left_out`: new
/// samples without an observable estimate) with the `references` of `topic`.
pub(super) fn compare(
    references: &mut [(u64, [f64; 3])],
    estimates: &[(u64, [f64; 3])],
    left_out: usize,
    topic: &str,
) -> Result<Comparison, ReplayError> {
    if references.is_empty() {
        return Err(ReplayError::Compare {
            topic: topic.to_owned(),
            why: "no message on this topic (it must be a geometry_msgs/msg/WrenchStamped)",
        });
    }
    references.sort_by_key(|(t, _)| *t);
    let mut est: [Vec<f64>; 3] = Default::default();
    let mut refv: [Vec<f64>; 3] = Default::default();
    let mut left_out = left_out;
    for (t, e) in estimates {
        let Some(f) = reference_at(references, *t) else {
            left_out += 1;
            continue;
        };
        for k in 0..3 {
            if let (Some(a), Some(b), Some(x), Some(y)) =
                (est.get_mut(k), refv.get_mut(k), e.get(k), f.get(k))
            {
                a.push(*x);
                b.push(*y);
            }
        }
    }
    let pairs = est.first().map_or(0, Vec::len);
    if pairs == 0 {
        return Err(ReplayError::Compare {
            topic: topic.to_owned(),
            why: "no observable estimate has a reference at or before it",
        });
    }
    let axis = |x: &[f64], y: &[f64]| {
        let e_ra = sar_estimator::error_measure::absolute_relative_error(x, y).unwrap_or(f64::NAN);
        let (mut sq, mut max) = (0.0f64, 0.0f64);
        for (a, b) in x.iter().zip(y) {
            let d = a - b;
            sq += d * d;
            max = max.max(d.abs());
        }
        AxisError {
            e_ra,
            rms_n: (sq / x.len() as f64).sqrt(),
            max_n: max,
        }
    };
    let [ex, ey, ez] = &est;
    let [rx, ry, rz] = &refv;
    Ok(Comparison {
        topic: topic.to_owned(),
        pairs,
        left_out,
        axes: [axis(ex, rx), axis(ey, ry), axis(ez, rz)],
    })
}
