// still_refine.h - a view that stops after moving frames drawn at a lower resolution,
// refined to full resolution a band of rows per frame (engine::RayCaster::render_rows), each
// frame's band sized to the frame budget, ending with the full frame bit for bit.
#pragma once
#include <cstdint>
#include <vector>

#include "isotouch/engine/frame_budget.h"
#include "isotouch/engine/raycast.h"

namespace isotouch::bench {

struct StillRefinement {
  std::vector<double> ms;  ///< each frame: its band's render_rows + its rows into the shown picture [ms]
  std::vector<int> rows;   ///< the rows each frame drew
  bool equal = false;      ///< each band's rows, and the picture the bands leave, are a full frame's (render()), bit for bit
  double total_ms() const;
  double max_ms() const;
};

/// The view `view` stopped after a frame drawn at rw x rh and shown upscaled to W x H in
/// `shown`. First (not timed) a full frame of the view, the truth, and the rw x rh frame
/// again (the buffers as the moving frames left them; its hits weigh each row's cost); then
/// the bands engine::RefineBands plans from row 0 down, each timed with its copy into `shown`.
/// Each band's rows replace the upscaled ones in `shown`; after the last, a render() of the
/// view reuses the bands' picture.
StillRefinement refine_still(engine::RayCaster& caster, const engine::CameraView& view,
                             const engine::RaycastStyle& style, int W, int H, int rw, int rh,
                             const engine::FrameBudget& budget, std::vector<std::uint32_t>& shown);

}  // namespace isotouch::bench
