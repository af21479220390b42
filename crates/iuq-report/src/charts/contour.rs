//! Contour lines of a density on a grid (marching squares), joined into polylines, and the
//! density levels that enclose a given probability mass.

use std::collections::HashMap;

/// A grid edge crossed by a contour: the cell corner it starts at and its direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Edge {
    i: usize,
    j: usize,
    horizontal: bool,
}

/// The density level whose superlevel set holds `mass` of the total on the grid `z` (highest
/// density region), e.g. 0.68 or 0.95.
pub(crate) fn level_for_mass(z: &[Vec<f64>], mass: f64) -> f64 {
    let mut values: Vec<f64> = z.iter().flatten().copied().collect();
    values.sort_by(|a, b| b.total_cmp(a));
    let total: f64 = values.iter().sum();
    let mut cumulative = 0.0;
    for &v in &values {
        cumulative += v;
        if cumulative >= mass * total {
            return v;
        }
    }
    values.last().copied().unwrap_or(0.0)
}

/// Contour lines of `z` at `level`, where `z[j][i]` is the value at `(xs[i], ys[j])`; each line
/// is a polyline (closed lines repeat their first point).
pub(crate) fn contour_lines(
    xs: &[f64],
    ys: &[f64],
    z: &[Vec<f64>],
    level: f64,
) -> Vec<Vec<(f64, f64)>> {
    let (nx, ny) = (xs.len(), ys.len());
    if nx < 2 || ny < 2 || z.len() != ny || z.iter().any(|row| row.len() != nx) {
        return Vec::new();
    }
    let crossing = |edge: Edge| -> (f64, f64) {
        let (i1, j1) = if edge.horizontal {
            (edge.i + 1, edge.j)
        } else {
            (edge.i, edge.j + 1)
        };
        let (a, b) = (z[edge.j][edge.i], z[j1][i1]);
        let t = if b != a {
            ((level - a) / (b - a)).clamp(0.0, 1.0)
        } else {
            0.5
        };
        (
            xs[edge.i] + t * (xs[i1] - xs[edge.i]),
            ys[edge.j] + t * (ys[j1] - ys[edge.j]),
        )
    };
    let mut segments: Vec<(Edge, Edge)> = Vec::new();
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let corners = [z[j][i], z[j][i + 1], z[j + 1][i + 1], z[j + 1][i]];
            let above = corners.map(|v| v > level);
            let bottom = Edge {
                i,
                j,
                horizontal: true,
            };
            let right = Edge {
                i: i + 1,
                j,
                horizontal: false,
            };
            let top = Edge {
                i,
                j: j + 1,
                horizontal: true,
            };
            let left = Edge {
                i,
                j,
                horizontal: false,
            };
            let saddle = above[0] == above[2] && above[1] == above[3] && above[0] != above[1];
            if saddle {
                let centre_above = corners.iter().sum::<f64>() / 4.0 > level;
                if centre_above == above[0] {
                    segments.push((bottom, right));
                    segments.push((left, top));
                } else {
                    segments.push((bottom, left));
                    segments.push((right, top));
                }
                continue;
            }
            let crossed: Vec<Edge> = [
                (above[0] != above[1], bottom),
                (above[1] != above[2], right),
                (above[3] != above[2], top),
                (above[0] != above[3], left),
            ]
            .into_iter()
            .filter_map(|(c, e)| c.then_some(e))
            .collect();
            if let [a, b] = crossed[..] {
                segments.push((a, b));
            }
        }
    }
    join(&segments)
        .into_iter()
        .map(|line| line.into_iter().map(crossing).collect())
        .collect()
}

/// Joins segments that share edges into polylines of edges; every edge belongs to at most two
/// segments, so the segments form simple paths and cycles.
fn join(segments: &[(Edge, Edge)]) -> Vec<Vec<Edge>> {
    let mut at: HashMap<Edge, Vec<usize>> = HashMap::new();
    for (k, (a, b)) in segments.iter().enumerate() {
        at.entry(*a).or_default().push(k);
        at.entry(*b).or_default().push(k);
    }
    let mut used = vec![false; segments.len()];
    let mut lines = Vec::new();
    for start in 0..segments.len() {
        if used[start] {
            continue;
        }
        used[start] = true;
        let mut line = std::collections::VecDeque::from([segments[start].0, segments[start].1]);
        // Extend forward from the back, then backward from the front.
        for forward in [true, false] {
            loop {
                let end = if forward { line.back() } else { line.front() };
                let Some(&end) = end else { break };
                let next = at
                    .get(&end)
                    .and_then(|ks| ks.iter().copied().find(|&k| !used[k]));
                let Some(k) = next else { break };
                used[k] = true;
                let (a, b) = segments[k];
                let other = if a == end { b } else { a };
                if forward {
                    line.push_back(other);
                } else {
                    line.push_front(other);
                }
            }
        }
        lines.push(line.into_iter().collect());
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cone_has_one_closed_circular_contour() {
        let grid: Vec<f64> = (0..41).map(|k| -2.0 + 0.1 * k as f64).collect();
        let z: Vec<Vec<f64>> = grid
            .iter()
            .map(|&y| grid.iter().map(|&x| 2.0 - (x * x + y * y).sqrt()).collect())
            .collect();
        let lines = contour_lines(&grid, &grid, &z, 1.0);
        assert_eq!(lines.len(), 1);
        let line = &lines[0];
        assert_eq!(line.first(), line.last());
        for &(x, y) in line {
            assert!(((x * x + y * y).sqrt() - 1.0).abs() < 0.02);
        }
    }

    #[test]
    fn mass_levels_are_ordered() {
        let z = vec![vec![1.0, 2.0], vec![3.0, 4.0]];
        assert_eq!(level_for_mass(&z, 0.4), 4.0);
        assert_eq!(level_for_mass(&z, 0.6), 3.0);
        assert_eq!(level_for_mass(&z, 1.0), 1.0);
    }
}
