// seg_nrrd.h - the segments of a 3D Slicer segmentation (`.seg.nrrd`): the header keys
// SegmentN_Name, SegmentN_LabelValue, SegmentN_Layer and SegmentN_Color of N = 0, 1, ...
// Reads the (key, value) pairs only (io::header_text_fields gives them); no voxels.
#pragma once
#include <array>
#include <string>
#include <utility>
#include <vector>

namespace isotouch::materials {

/// One segment as the header gives it.
struct Segment {
  int index = 0;                    ///< N in SegmentN_*
  std::string name;                 ///< SegmentN_Name, not empty, unique
  int label_value = 0;              ///< SegmentN_LabelValue, in [1, 65535], unique
  int layer = 0;                    ///< SegmentN_Layer; only 0 is read (one 3D label map)
  std::array<double, 3> color{};    ///< SegmentN_Color, "R G B", each in [0, 1]
};

/// Most segments read from one file.
inline constexpr int kMaxSegments = 256;

/// The segments of a `.seg.nrrd` header, by index. Every N from 0 to the largest index any
/// SegmentN_ key names must have all four keys; keys of other forms are ignored.
/// @param path named in messages.
/// @throws MaterialError "PATH: header key 'Segment1_LabelValue': ..." naming the key and
///         its value: no segment at all, a missing key, an index above kMaxSegments - 1, a
///         label value that is not an integer in [1, 65535] or repeats, a layer other than 0
///         (overlapping segments: export a label map), a colour that is not 3 numbers in
///         [0, 1], an empty or repeated name.
std::vector<Segment> parse_seg_nrrd_segments(const std::vector<std::pair<std::string, std::string>>& keys,
                                             const std::string& path);

}  // namespace isotouch::materials
