//! Euclidean clustering: two points are in the same cluster when a chain of points, each within `radius` of the
//! next, joins them (single linkage). A hash grid of `radius`-sized cells makes it near-linear: a point's
//! neighbours can only be in its own or the adjacent cells, and every candidate is checked with the exact
//! distance, so the result equals the quadratic definition.
//!
//! Output is deterministic: clusters are ordered by their smallest point index, indices ascending within each.

use std::collections::HashMap;

/// Clusters of at least `min_points` points (indices into `points`). Non-finite points are ignored.
pub fn euclidean_clusters(points: &[[f32; 3]], radius: f32, min_points: usize) -> Vec<Vec<usize>> {
    if !(radius.is_finite() && radius > 0.0) {
        tracing::warn!(radius, "clustering radius must be positive and finite; no clusters");
        return Vec::new();
    }
    let cell_of = |p: &[f32; 3]| p.map(|v| (v / radius).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (index, point) in points.iter().enumerate() {
        if point.iter().all(|v| v.is_finite()) {
            grid.entry(cell_of(point)).or_default().push(index);
        }
    }
    let radius2 = radius * radius;
    let mut visited = vec![false; points.len()];
    let mut clusters = Vec::new();
    let mut stack = Vec::new();
    for seed in 0..points.len() {
        if visited[seed] || !points[seed].iter().all(|v| v.is_finite()) {
            continue;
        }
        visited[seed] = true;
        stack.push(seed);
        let mut cluster = Vec::new();
        while let Some(index) = stack.pop() {
            cluster.push(index);
            let point = points[index];
            let cell = cell_of(&point);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(candidates) = grid.get(&[cell[0] + dx, cell[1] + dy, cell[2] + dz]) else { continue };
                        for &other in candidates {
                            if visited[other] {
                                continue;
                            }
                            let q = points[other];
                            let d2 = (0..3).map(|k| (q[k] - point[k]).powi(2)).sum::<f32>();
                            if d2 <= radius2 {
                                visited[other] = true;
                                stack.push(other);
                            }
                        }
                    }
                }
            }
        }
        if cluster.len() >= min_points {
            cluster.sort_unstable();
            clusters.push(cluster);
        }
    }
    clusters
}
