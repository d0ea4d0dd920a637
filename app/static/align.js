// Two previews in one orientation. Every preview is in the engine's canonical frame
// (principal axes: largest spread across, least towards the viewer, limbs down), which
// fixes each axis only up to its sign: a quadruped in another pose may come out facing
// the other way. Of the four rotations that flip two axes' signs (a half turn about the
// third), the match is drawn turned by the one that lays it closest onto the query.

// The proper rotations among the axis sign flips: identity and the half turns about z,
// y and x (two signs flipped, so never a mirror image).
export const TURNS = [
  [1, 1, 1],
  [-1, -1, 1],
  [-1, 1, -1],
  [1, -1, -1],
];

// At most `count` of the (n, 3) points, spread over them by a fixed stride.
export function samplePoints(points, count = 400) {
  const stride = Math.max(1, Math.floor(points.length / count));
  const kept = [];
  for (let i = 0; i < points.length && kept.length < count; i += stride) kept.push(points[i]);
  return kept;
}

// The mean distance from each of `a` to its nearest of `b` (brute force: a few hundred
// points each).
function meanNearest(a, b) {
  let total = 0;
  for (const [x, y, z] of a) {
    let best = Infinity;
    for (const [u, v, w] of b) {
      const d = (x - u) ** 2 + (y - v) ** 2 + (z - w) ** 2;
      if (d < best) best = d;
    }
    total += Math.sqrt(best);
  }
  return total / a.length;
}

// The turn of `match` (points) that lays it closest onto `query`, by the symmetric mean
// nearest-point distance, and that distance for every turn.
export function bestTurn(query, match) {
  const q = samplePoints(query);
  const m = samplePoints(match);
  const distances = TURNS.map(([sx, sy, sz]) => {
    const turned = m.map(([x, y, z]) => [sx * x, sy * y, sz * z]);
    return meanNearest(q, turned) + meanNearest(turned, q);
  });
  const best = distances.indexOf(Math.min(...distances));
  return { turn: TURNS[best], distances };
}
