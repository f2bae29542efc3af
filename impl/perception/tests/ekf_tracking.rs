//! EKF tracks converge on synthetic moving targets with known truth (seeded noise), and the tracker's birth,
//! confirmation, association and death rules hold.

use perception::ekf::{Detection, Measurement, TrackStatus, Tracker, TrackerConfig};

/// Deterministic Gaussian noise: xorshift64* and Box-Muller.
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn gaussian(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

fn range_bearing(truth: [f64; 2], noise: &mut Noise, sigma_r: f64, sigma_b: f64) -> Measurement {
    Measurement::RangeBearing {
        range_mm: truth[0].hypot(truth[1]) + sigma_r * noise.gaussian(),
        bearing_rad: truth[1].atan2(truth[0]) + sigma_b * noise.gaussian(),
        range_sigma_mm: sigma_r,
        bearing_sigma_rad: sigma_b,
    }
}

#[test]
fn range_bearing_track_converges_on_a_constant_velocity_target() {
    let mut noise = Noise(0x9E37_79B9_7F4A_7C15);
    // The target truly moves at constant velocity: little process noise (0.05 m/s² white acceleration).
    let mut tracker = Tracker::new(TrackerConfig { process_noise: 2500.0, ..TrackerConfig::default() });
    let (start, velocity, dt) = ([3000.0, -1500.0], [-250.0, 400.0], 0.1);
    let mut errors = Vec::new();
    for step in 0..150 {
        let t = f64::from(step) * dt;
        let truth = [start[0] + velocity[0] * t, start[1] + velocity[1] * t];
        let measurement = range_bearing(truth, &mut noise, 20.0, 0.01);
        tracker.step(dt, &[Detection { tag: 0, measurement }]);
        assert_eq!(tracker.tracks().len(), 1, "one target, one track (step {step})");
        let track = &tracker.tracks()[0];
        assert_eq!(track.id, 1, "the track is never dropped and reborn");
        let p = track.filter.position_mm();
        errors.push(((p[0] - truth[0]).hypot(p[1] - truth[1]), truth));
    }
    let track = &tracker.tracks()[0];
    assert_eq!(track.status, TrackStatus::Confirmed);
    let v = track.filter.velocity_mm_s();
    assert!((v[0] - velocity[0]).hypot(v[1] - velocity[1]) < 60.0, "velocity {v:?} vs {velocity:?}");
    let late: f64 = errors[100..].iter().map(|(e, _)| e).sum::<f64>() / 50.0;
    let early: f64 = errors[..10].iter().map(|(e, _)| e).sum::<f64>() / 10.0;
    assert!(late < 30.0, "mean late position error {late} mm");
    assert!(late < early, "error decreases: early {early}, late {late}");
    // Covariance is consistent with the error: the truth lies inside the 99 % ellipse at the end.
    let cov = track.filter.position_covariance();
    let truth = errors.last().unwrap().1;
    let e = nalgebra::Vector2::new(track.filter.x[0] - truth[0], track.filter.x[1] - truth[1]);
    let d2 = (e.transpose() * cov.try_inverse().unwrap() * e)[(0, 0)];
    assert!(d2 < 9.21, "truth at Mahalanobis² {d2}");
}

#[test]
fn two_crossing_free_targets_keep_their_ids_and_a_vanished_one_dies() {
    let mut noise = Noise(42);
    let config = TrackerConfig::default();
    let max_misses = config.max_misses_confirmed;
    let mut tracker = Tracker::new(config);
    let cov = [[100.0, 0.0], [0.0, 100.0]];
    let cartesian = |p: [f64; 2], noise: &mut Noise| Measurement::Cartesian {
        position_mm: [p[0] + 10.0 * noise.gaussian(), p[1] + 10.0 * noise.gaussian()],
        covariance_mm2: cov,
    };
    let dt = 0.1;
    for step in 0..40 {
        let t = f64::from(step) * dt;
        let a = [1000.0 + 200.0 * t, 0.0];
        let b = [1000.0, 2000.0 - 300.0 * t];
        let detections = [
            Detection { tag: 0, measurement: cartesian(b, &mut noise) },
            Detection { tag: 0, measurement: cartesian(a, &mut noise) },
        ];
        // The order of detections changes every step: association must not depend on it.
        let order: Vec<Detection> =
            if step % 2 == 0 { detections.to_vec() } else { detections.iter().rev().copied().collect() };
        tracker.step(dt, &order);
        if step == 1 {
            assert!(tracker.tracks().iter().all(|t| t.status == TrackStatus::Tentative));
        }
    }
    let ids: Vec<(u64, [f64; 2])> = tracker.confirmed().map(|t| (t.id, t.filter.position_mm())).collect();
    assert_eq!(ids.len(), 2);
    // Track 1 was born from target b (listed first at step 0), track 2 from a.
    let by_id = |id: u64| ids.iter().find(|(i, _)| *i == id).unwrap().1;
    assert!((by_id(1)[1] - (2000.0 - 300.0 * 3.9)).abs() < 50.0, "{:?}", by_id(1));
    assert!((by_id(2)[0] - (1000.0 + 200.0 * 3.9)).abs() < 50.0, "{:?}", by_id(2));
    // Target b vanishes: its track survives `max_misses_confirmed` misses, then dies.
    for step in 0..=max_misses {
        let a = [1000.0 + 200.0 * (4.0 + f64::from(step) * dt), 0.0];
        tracker.step(dt, &[Detection { tag: 0, measurement: cartesian(a, &mut noise) }]);
        let alive = tracker.tracks().iter().any(|t| t.id == 1);
        assert_eq!(alive, step < max_misses, "step {step}");
    }
    assert_eq!(tracker.died(), &[1]);
    assert_eq!(tracker.tracks().iter().map(|t| t.id).collect::<Vec<_>>(), vec![2]);
}

#[test]
fn tags_separate_tracks_and_far_detections_start_new_ones() {
    let mut tracker = Tracker::new(TrackerConfig::default());
    let at = |x: f64| Measurement::Cartesian { position_mm: [x, 0.0], covariance_mm2: [[100.0, 0.0], [0.0, 100.0]] };
    tracker.step(0.1, &[Detection { tag: 1, measurement: at(0.0) }]);
    // Same place, other tag: a new track, not an update.
    tracker.step(0.1, &[Detection { tag: 1, measurement: at(0.0) }, Detection { tag: 2, measurement: at(0.0) }]);
    assert_eq!(tracker.tracks().iter().map(|t| (t.id, t.tag, t.hits)).collect::<Vec<_>>(), vec![(1, 1, 2), (2, 2, 1)]);
    // Far outside the gate: a new track; the tentative tag-2 track misses twice and dies.
    tracker.step(0.1, &[Detection { tag: 1, measurement: at(0.0) }, Detection { tag: 1, measurement: at(5000.0) }]);
    assert_eq!(tracker.tracks().len(), 3);
    assert_eq!(tracker.tracks()[0].status, TrackStatus::Confirmed);
    tracker.step(0.1, &[Detection { tag: 1, measurement: at(0.0) }]);
    assert_eq!(tracker.died(), &[2]);
}
