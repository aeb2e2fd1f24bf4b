// Dynamic resolution aimed at a frame-rate goal: a pure controller (state in, one fps
// sample in, new state out; no DOM, no clock), driven once a second by main.js with the
// page's animation frames per second. The view renders at `scaleOf(state)` x the
// canvas' CSS size.
//
// - Down: when the last `downAfter` samples (s) all ran below `target` fps, one step
//   finer (fewer pixels).
// - Up: after `upWait` consecutive samples above `high` fps (well above the target:
//   vsync-bound at 60 Hz), one step coarser (more pixels).
// - Backoff, so the page settles instead of oscillating: a step up that falls below the
//   target within `settle` seconds (a step down follows it) doubles `upWait` (up to
//   `maxWait`); a step up that holds for `settle` seconds resets it to `upAfter`.
// - Pinned (`pin(state, scale)`, e.g. riderlive.setRenderScale(0.5)): no adaptation
//   until `pin(state, null)`, which resumes automatically from the step nearest the
//   pinned scale.

/** Render scales, coarsest first; targets in animation frames per second; times in one-second samples. */
export const DEFAULTS = Object.freeze({
  scales: Object.freeze([1, 0.85, 0.75, 0.6, 0.5]),
  target: 55,
  high: 58,
  downAfter: 2,
  upAfter: 4,
  settle: 10,
  backoff: 2,
  maxWait: 64,
});

/** The controller at scale `scales[step]`, with fresh counters. */
export function initial(params = DEFAULTS, step = 0) {
  return { step, pinned: null, below: 0, above: 0, upWait: params.upAfter, sinceUp: null };
}

/** The render scale the state asks for (the pinned one if pinned). */
export function scaleOf(state, params = DEFAULTS) {
  return state.pinned ?? params.scales[state.step];
}

/** The step whose scale is nearest `scale`. */
function nearest(scale, params) {
  let best = 0;
  params.scales.forEach((s, i) => {
    if (Math.abs(s - scale) < Math.abs(params.scales[best] - scale)) best = i;
  });
  return best;
}

/** Pin the render scale (a number in (0, 1]) or, with null, go back to automatic. */
export function pin(state, scale, params = DEFAULTS) {
  if (scale === null || scale === undefined) {
    if (state.pinned === null) return state;
    return { ...initial(params, nearest(state.pinned, params)), upWait: state.upWait };
  }
  if (!(scale > 0 && scale <= 1)) throw new RangeError(`render scale ${scale}: expected a number in (0, 1] or null`);
  return { ...state, pinned: scale, below: 0, above: 0, sinceUp: null };
}

/** The state after one second that ran at `fps` animation frames per second. */
export function next(state, fps, params = DEFAULTS) {
  if (state.pinned !== null) return state;
  const last = params.scales.length - 1;
  let { step, below, above, upWait, sinceUp } = state;
  if (sinceUp !== null) sinceUp += 1;
  below = fps < params.target ? below + 1 : 0;
  above = fps > params.high ? above + 1 : 0;
  if (below >= params.downAfter && step < last) {
    if (sinceUp !== null && sinceUp <= params.settle) upWait = Math.min(params.maxWait, upWait * params.backoff);
    return { step: step + 1, pinned: null, below: 0, above: 0, upWait, sinceUp: null };
  }
  if (sinceUp !== null && sinceUp > params.settle) {
    upWait = params.upAfter; // the last step up held
    sinceUp = null;
  }
  if (above >= upWait && step > 0) return { step: step - 1, pinned: null, below: 0, above: 0, upWait, sinceUp: 0 };
  return { step, pinned: null, below, above, upWait, sinceUp };
}
