//! A constant-velocity extended Kalman filter in 2-D and a multi-target tracker built on it.
//!
//! **Model.** State `x = [px, py, vx, vy]` (mm, mm/s) in the sensor's frame; prediction over `dt` seconds with
//! `F = [[I, dt·I], [0, I]]` and the white-acceleration process noise `Q = q·[[dt³/3·I, dt²/2·I], [dt²/2·I,
//! dt·I]]` (`q` in mm²/s³). Measurements are either Cartesian positions (linear) or range and bearing
//! (`h(x) = [√(px²+py²), atan2(py, px)]`, linearised with its Jacobian; the bearing innovation is wrapped to
//! (-π, π]).
//!
//! **Tracker rules.** Each [`Tracker::step`]: (1) every track is predicted; (2) gating: a measurement may update a
//! track only if they share a tag (e.g. a colour class) and the squared Mahalanobis distance of the innovation
//! `yᵀS⁻¹y` is below `gate_chi2` (default 9.21: 99 % for 2 degrees of freedom); (3) association: global nearest
//! neighbour, greedily taking gated pairs in increasing distance, each track and measurement at most once; (4)
//! update of the associated tracks (hits + 1, misses reset); (5) **birth**: each measurement left over starts a
//! *tentative* track at its position with zero velocity and `initial_speed_sigma` uncertainty; (6)
//! **confirmation**: a tentative track with `confirm_hits` hits becomes *confirmed*; (7) **death**: a track missed
//! more than `max_misses_tentative` (tentative) or `max_misses_confirmed` (confirmed) consecutive steps is removed,
//! as is any track whose covariance stops being finite. Track ids are never reused within a tracker.

use nalgebra::{Matrix2, Matrix2x4, Matrix4, SymmetricEigen, Vector2, Vector4};

/// A measurement of one detection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Measurement {
    /// A position (mm) with its covariance (mm²).
    Cartesian {
        /// Position.
        position_mm: [f64; 2],
        /// Covariance.
        covariance_mm2: [[f64; 2]; 2],
    },
    /// Range (mm) and bearing (rad) from the sensor, with standard deviations.
    RangeBearing {
        /// Range.
        range_mm: f64,
        /// Bearing, counter-clockwise from x.
        bearing_rad: f64,
        /// Range standard deviation.
        range_sigma_mm: f64,
        /// Bearing standard deviation.
        bearing_sigma_rad: f64,
    },
}

impl Measurement {
    /// The measured position in Cartesian coordinates.
    pub fn position_mm(&self) -> [f64; 2] {
        match *self {
            Self::Cartesian { position_mm, .. } => position_mm,
            Self::RangeBearing { range_mm, bearing_rad, .. } => {
                [range_mm * bearing_rad.cos(), range_mm * bearing_rad.sin()]
            }
        }
    }

    fn is_finite(&self) -> bool {
        match *self {
            Self::Cartesian { position_mm, covariance_mm2 } => {
                position_mm.iter().chain(covariance_mm2.iter().flatten()).all(|v| v.is_finite())
            }
            Self::RangeBearing { range_mm, bearing_rad, range_sigma_mm, bearing_sigma_rad } => {
                [range_mm, bearing_rad, range_sigma_mm, bearing_sigma_rad].iter().all(|v| v.is_finite())
            }
        }
    }

    /// Innovation `z - h(x)`, Jacobian `H` and noise `R` at state `x`.
    fn linearise(&self, x: &Vector4<f64>) -> Option<(Vector2<f64>, Matrix2x4<f64>, Matrix2<f64>)> {
        match *self {
            Self::Cartesian { position_mm, covariance_mm2 } => {
                let h = Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
                let y = Vector2::new(position_mm[0] - x[0], position_mm[1] - x[1]);
                let r = Matrix2::new(
                    covariance_mm2[0][0],
                    covariance_mm2[0][1],
                    covariance_mm2[1][0],
                    covariance_mm2[1][1],
                );
                Some((y, h, r))
            }
            Self::RangeBearing { range_mm, bearing_rad, range_sigma_mm, bearing_sigma_rad } => {
                let (px, py) = (x[0], x[1]);
                let r2 = px * px + py * py;
                if r2 < 1e-6 {
                    return None; // h is not differentiable at the sensor's origin.
                }
                let r = r2.sqrt();
                let h = Matrix2x4::new(px / r, py / r, 0.0, 0.0, -py / r2, px / r2, 0.0, 0.0);
                let y = Vector2::new(range_mm - r, wrap_angle(bearing_rad - py.atan2(px)));
                let noise = Matrix2::new(range_sigma_mm.powi(2), 0.0, 0.0, bearing_sigma_rad.powi(2));
                Some((y, h, noise))
            }
        }
    }
}

/// Wraps an angle to (-π, π].
pub fn wrap_angle(angle: f64) -> f64 {
    let wrapped = (angle + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if wrapped <= -std::f64::consts::PI { wrapped + std::f64::consts::TAU } else { wrapped }
}

/// The filter of one target.
#[derive(Debug, Clone, PartialEq)]
pub struct Ekf {
    /// State `[px, py, vx, vy]`, mm and mm/s.
    pub x: Vector4<f64>,
    /// State covariance.
    pub p: Matrix4<f64>,
}

impl Ekf {
    /// A filter at `position_mm` with position covariance `position_cov` and isotropic speed uncertainty.
    pub fn new(position_mm: [f64; 2], position_cov: Matrix2<f64>, speed_sigma_mm_s: f64) -> Self {
        let mut p = Matrix4::zeros();
        p.fixed_view_mut::<2, 2>(0, 0).copy_from(&position_cov);
        p[(2, 2)] = speed_sigma_mm_s.powi(2);
        p[(3, 3)] = speed_sigma_mm_s.powi(2);
        Self { x: Vector4::new(position_mm[0], position_mm[1], 0.0, 0.0), p }
    }

    /// Predicts `dt_s` seconds ahead with process noise density `q` (mm²/s³).
    pub fn predict(&mut self, dt_s: f64, q: f64) {
        let mut f = Matrix4::identity();
        f[(0, 2)] = dt_s;
        f[(1, 3)] = dt_s;
        let (a, b, c) = (dt_s.powi(3) / 3.0, dt_s.powi(2) / 2.0, dt_s);
        #[rustfmt::skip]
        let noise = Matrix4::new(
            a, 0.0, b, 0.0,
            0.0, a, 0.0, b,
            b, 0.0, c, 0.0,
            0.0, b, 0.0, c,
        ) * q;
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + noise;
    }

    /// Squared Mahalanobis distance of a measurement's innovation (`None` if it cannot be computed).
    pub fn mahalanobis2(&self, measurement: &Measurement) -> Option<f64> {
        let (y, h, r) = measurement.linearise(&self.x)?;
        let s = h * self.p * h.transpose() + r;
        let d2 = (y.transpose() * s.try_inverse()? * y)[(0, 0)];
        d2.is_finite().then_some(d2)
    }

    /// Updates with a measurement (Joseph form, which keeps `P` symmetric positive semi-definite). Returns false
    /// and leaves the filter unchanged if the innovation covariance is singular.
    pub fn update(&mut self, measurement: &Measurement) -> bool {
        let Some((y, h, r)) = measurement.linearise(&self.x) else { return false };
        let s = h * self.p * h.transpose() + r;
        let Some(s_inv) = s.try_inverse() else { return false };
        let k = self.p * h.transpose() * s_inv;
        let i_kh = Matrix4::identity() - k * h;
        self.x += k * y;
        self.p = i_kh * self.p * i_kh.transpose() + k * r * k.transpose();
        true
    }

    /// Position `[x, y]`, mm.
    pub fn position_mm(&self) -> [f64; 2] {
        [self.x[0], self.x[1]]
    }

    /// Velocity `[vx, vy]`, mm/s.
    pub fn velocity_mm_s(&self) -> [f64; 2] {
        [self.x[2], self.x[3]]
    }

    /// Position covariance, mm².
    pub fn position_covariance(&self) -> Matrix2<f64> {
        self.p.fixed_view::<2, 2>(0, 0).into_owned()
    }

    /// The ellipse holding the position with the probability of `chi2` (e.g. 5.99 for 95 %): half-axes (mm) and
    /// the rotation of the first axis (rad).
    pub fn position_ellipse(&self, chi2: f64) -> (f64, f64, f64) {
        let cov = self.position_covariance();
        let cov = (cov + cov.transpose()) * 0.5;
        let eigen = SymmetricEigen::new(cov);
        let (major, minor) = if eigen.eigenvalues[0] >= eigen.eigenvalues[1] { (0, 1) } else { (1, 0) };
        let axis = eigen.eigenvectors.column(major);
        let radius = |value: f64| (chi2 * value.max(0.0)).sqrt();
        (radius(eigen.eigenvalues[major]), radius(eigen.eigenvalues[minor]), axis[1].atan2(axis[0]))
    }

    fn is_finite(&self) -> bool {
        self.x.iter().chain(self.p.iter()).all(|v| v.is_finite())
    }
}

/// Tracker parameters (see the module docs for the rules).
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerConfig {
    /// Process noise density, mm²/s³.
    pub process_noise: f64,
    /// Gate on the squared Mahalanobis distance.
    pub gate_chi2: f64,
    /// Hits that confirm a tentative track.
    pub confirm_hits: u32,
    /// Consecutive misses a tentative track survives.
    pub max_misses_tentative: u32,
    /// Consecutive misses a confirmed track survives.
    pub max_misses_confirmed: u32,
    /// Speed standard deviation of a new track, mm/s.
    pub initial_speed_sigma_mm_s: f64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            process_noise: 250_000.0,
            gate_chi2: 9.21,
            confirm_hits: 3,
            max_misses_tentative: 1,
            max_misses_confirmed: 5,
            initial_speed_sigma_mm_s: 1000.0,
        }
    }
}

/// Whether a track has been confirmed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TrackStatus {
    /// Newly born, not yet trusted.
    Tentative,
    /// Seen often enough to report.
    Confirmed,
}

/// One tracked target.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// Unique within its tracker.
    pub id: u64,
    /// Association tag (e.g. colour class); measurements only update tracks with the same tag.
    pub tag: u32,
    /// The filter.
    pub filter: Ekf,
    /// Status.
    pub status: TrackStatus,
    /// Updates so far.
    pub hits: u32,
    /// Consecutive steps without an update.
    pub misses: u32,
}

/// A measurement with its association tag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Tag (e.g. colour class).
    pub tag: u32,
    /// What was measured.
    pub measurement: Measurement,
}

/// A list of EKF tracks maintained from detections.
#[derive(Debug, Clone, Default)]
pub struct Tracker {
    config: TrackerConfig,
    tracks: Vec<Track>,
    next_id: u64,
    /// Track ids removed by the last step.
    died: Vec<u64>,
}

impl Tracker {
    /// An empty tracker.
    pub fn new(config: TrackerConfig) -> Self {
        Self { config, tracks: Vec::new(), next_id: 1, died: Vec::new() }
    }

    /// The live tracks (tentative and confirmed), in birth order.
    pub fn tracks(&self) -> &[Track] {
        &self.tracks
    }

    /// The confirmed tracks.
    pub fn confirmed(&self) -> impl Iterator<Item = &Track> {
        self.tracks.iter().filter(|t| t.status == TrackStatus::Confirmed)
    }

    /// Ids of the tracks the last step removed.
    pub fn died(&self) -> &[u64] {
        &self.died
    }

    /// The parameters.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// Predicts every track `dt_s` ahead and folds in one batch of detections (see the module docs).
    /// Non-finite detections are skipped with a warning.
    pub fn step(&mut self, dt_s: f64, detections: &[Detection]) {
        self.died.clear();
        let dt_s = if dt_s.is_finite() && dt_s >= 0.0 { dt_s } else { 0.0 };
        for track in &mut self.tracks {
            track.filter.predict(dt_s, self.config.process_noise);
        }
        let valid: Vec<&Detection> = detections
            .iter()
            .filter(|d| {
                let ok = d.measurement.is_finite();
                if !ok {
                    tracing::warn!(?d, "skipping non-finite detection");
                }
                ok
            })
            .collect();
        let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
        for (ti, track) in self.tracks.iter().enumerate() {
            for (di, detection) in valid.iter().enumerate() {
                if detection.tag != track.tag {
                    continue;
                }
                if let Some(d2) = track.filter.mahalanobis2(&detection.measurement)
                    && d2 < self.config.gate_chi2
                {
                    pairs.push((d2, ti, di));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let mut track_used = vec![false; self.tracks.len()];
        let mut detection_used = vec![false; valid.len()];
        for (_, ti, di) in pairs {
            if track_used[ti] || detection_used[di] {
                continue;
            }
            track_used[ti] = true;
            detection_used[di] = true;
            let track = &mut self.tracks[ti];
            if track.filter.update(&valid[di].measurement) {
                track.hits += 1;
                track.misses = 0;
                if track.status == TrackStatus::Tentative && track.hits >= self.config.confirm_hits {
                    track.status = TrackStatus::Confirmed;
                }
            } else {
                track.misses += 1;
            }
        }
        for (ti, track) in self.tracks.iter_mut().enumerate() {
            if !track_used[ti] {
                track.misses += 1;
            }
        }
        let config = &self.config;
        let died = &mut self.died;
        self.tracks.retain(|track| {
            let limit = match track.status {
                TrackStatus::Tentative => config.max_misses_tentative,
                TrackStatus::Confirmed => config.max_misses_confirmed,
            };
            let keep = track.misses <= limit && track.filter.is_finite();
            if !keep {
                died.push(track.id);
            }
            keep
        });
        for (di, detection) in valid.iter().enumerate() {
            if detection_used[di] {
                continue;
            }
            let position_cov = match detection.measurement {
                Measurement::Cartesian { covariance_mm2, .. } => {
                    Matrix2::new(covariance_mm2[0][0], covariance_mm2[0][1], covariance_mm2[1][0], covariance_mm2[1][1])
                }
                Measurement::RangeBearing { range_mm, range_sigma_mm, bearing_sigma_rad, .. } => {
                    let sigma = range_sigma_mm.max(range_mm * bearing_sigma_rad);
                    Matrix2::identity() * sigma * sigma
                }
            };
            let filter =
                Ekf::new(detection.measurement.position_mm(), position_cov, self.config.initial_speed_sigma_mm_s);
            let status = if self.config.confirm_hits <= 1 { TrackStatus::Confirmed } else { TrackStatus::Tentative };
            self.tracks.push(Track { id: self.next_id, tag: detection.tag, filter, status, hits: 1, misses: 0 });
            self.next_id += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_angle_stays_in_range() {
        for angle in [-10.0, -std::f64::consts::PI, 0.0, 3.0, std::f64::consts::PI, 7.0] {
            let w = wrap_angle(angle);
            assert!(w > -std::f64::consts::PI && w <= std::f64::consts::PI, "{angle} -> {w}");
            assert!(((w - angle) / std::f64::consts::TAU).fract().abs() < 1e-9 || (w - angle).abs() < 1e-9);
        }
    }

    #[test]
    fn ellipse_axes_follow_the_covariance() {
        let mut filter = Ekf::new([0.0, 0.0], Matrix2::new(400.0, 0.0, 0.0, 100.0), 1.0);
        let (major, minor, angle) = filter.position_ellipse(1.0);
        assert!((major - 20.0).abs() < 1e-9 && (minor - 10.0).abs() < 1e-9 && angle.sin().abs() < 1e-9);
        filter.p[(0, 0)] = 100.0;
        filter.p[(1, 1)] = 400.0;
        let (_, _, angle) = filter.position_ellipse(1.0);
        assert!(angle.cos().abs() < 1e-9);
    }

    #[test]
    fn non_finite_detections_are_skipped() {
        let mut tracker = Tracker::new(TrackerConfig::default());
        let nan = Measurement::Cartesian { position_mm: [f64::NAN, 0.0], covariance_mm2: [[1.0, 0.0], [0.0, 1.0]] };
        tracker.step(0.1, &[Detection { tag: 0, measurement: nan }]);
        assert!(tracker.tracks().is_empty());
    }
}
