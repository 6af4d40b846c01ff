//! ORB-SLAM's quadtree distribution: split the image region into nodes until there are as
//! many nodes as features wanted, then keep the strongest corner of each node, so features
//! spread over the whole image instead of piling up on the most textured part.

use super::fast::Corner;

struct Node {
    x0: f32,
    y0: f32,
    x1: f32,
    y1: f32,
    points: Vec<u32>,
}

impl Node {
    fn splittable(&self) -> bool {
        self.points.len() > 1 && self.x1 - self.x0 >= 2.0 && self.y1 - self.y0 >= 2.0
    }

    fn split(&self, corners: &[Corner]) -> [Node; 4] {
        let (xm, ym) = ((self.x0 + self.x1) * 0.5, (self.y0 + self.y1) * 0.5);
        let mut kids = [
            Node { x0: self.x0, y0: self.y0, x1: xm, y1: ym, points: Vec::new() },
            Node { x0: xm, y0: self.y0, x1: self.x1, y1: ym, points: Vec::new() },
            Node { x0: self.x0, y0: ym, x1: xm, y1: self.y1, points: Vec::new() },
            Node { x0: xm, y0: ym, x1: self.x1, y1: self.y1, points: Vec::new() },
        ];
        for &i in &self.points {
            let c = corners[i as usize];
            let right = usize::from(f32::from(c.x) >= xm);
            let below = usize::from(f32::from(c.y) >= ym);
            kids[below * 2 + right].points.push(i);
        }
        kids
    }
}

/// Indices into `corners` (all inside `[x0, x1) x [y0, y1)`) of at most about `wanted`
/// corners, the strongest (by `response`, aligned with `corners`) of each quadtree node. May
/// return a few more than `wanted` (a split makes up to four nodes); the caller trims.
pub(crate) fn distribute(corners: &[Corner], response: &[f32], wanted: usize, [x0, y0, x1, y1]: [f32; 4]) -> Vec<u32> {
    if corners.is_empty() || wanted == 0 || x1 <= x0 || y1 <= y0 {
        return Vec::new();
    }
    // Initial nodes: about square, side by side along the longer axis.
    let n_ini = ((x1 - x0) / (y1 - y0)).round().max(1.0) as usize;
    let hx = (x1 - x0) / n_ini as f32;
    let mut nodes: Vec<Node> = (0..n_ini)
        .map(|i| Node { x0: x0 + hx * i as f32, y0, x1: x0 + hx * (i + 1) as f32, y1, points: Vec::new() })
        .collect();
    for (i, c) in corners.iter().enumerate() {
        let k = (((f32::from(c.x) - x0) / hx) as usize).min(n_ini - 1);
        nodes[k].points.push(i as u32);
    }
    nodes.retain(|n| !n.points.is_empty());
    loop {
        if nodes.len() >= wanted || !nodes.iter().any(Node::splittable) {
            break;
        }
        let expandable = nodes.iter().filter(|n| n.splittable()).count();
        if nodes.len() + 3 * expandable <= wanted {
            // Split every node with more than one corner.
            let mut next = Vec::with_capacity(nodes.len() + 3 * expandable);
            for n in nodes {
                if n.splittable() {
                    next.extend(n.split(corners).into_iter().filter(|k| !k.points.is_empty()));
                } else {
                    next.push(n);
                }
            }
            nodes = next;
        } else {
            // Close to the target: split the most crowded nodes first, one at a time.
            nodes.sort_by_key(|n| std::cmp::Reverse(n.points.len()));
            let mut i = 0;
            while nodes.len() < wanted && i < nodes.len() {
                if nodes[i].splittable() {
                    let kids = nodes[i].split(corners);
                    nodes.swap_remove(i);
                    nodes.extend(kids.into_iter().filter(|k| !k.points.is_empty()));
                } else {
                    i += 1;
                }
            }
            break;
        }
    }
    nodes
        .iter()
        .filter_map(|n| {
            n.points.iter().copied().max_by(|&a, &b| {
                let (ra, rb) = (response[a as usize], response[b as usize]);
                ra.total_cmp(&rb).then(b.cmp(&a))
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spreads_over_the_region_and_keeps_the_strongest() {
        // A dense strong cluster in one corner and weaker corners everywhere else.
        let mut corners = Vec::new();
        for y in 0..20u16 {
            for x in 0..20u16 {
                corners.push(Corner { x: 10 + x, y: 10 + y, score: 200 });
            }
        }
        for y in (0..480u16).step_by(40) {
            for x in (0..640u16).step_by(40) {
                corners.push(Corner { x: x + 5, y: y + 5, score: 30 });
            }
        }
        let response: Vec<f32> = corners.iter().map(|c| f32::from(c.score)).collect();
        let kept = distribute(&corners, &response, 100, [0.0, 0.0, 640.0, 480.0]);
        assert!((100..=103).contains(&kept.len()), "{}", kept.len());
        let far = kept.iter().filter(|&&i| corners[i as usize].x > 320 && corners[i as usize].y > 240).count();
        assert!(far >= 15, "the far quadrant got {far}");
        assert!(distribute(&[], &[], 10, [0.0, 0.0, 10.0, 10.0]).is_empty());
    }
}
