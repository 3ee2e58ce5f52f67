#pragma once
// Mirror-image augmentation: a drive seen in a horizontal mirror is another plausible drive in which every turn goes
// the other way. Frames flip left-right, curvature changes sign, and the words "left" and "right" swap in captions
// and labels. Recorded steering is rarely balanced between left and right (traffic keeps to one side: our synth
// drives keep left, as in the UK, so a turn towards the kerb and one across the road look different); the mirror
// balances it exactly.
// Mirrored episodes get the id `<source id>-mirror` and are held out with their source (data/geofence.h), so a
// validation road never reaches training in mirror image.
#include <string>

#include <nlohmann/json.hpp>

namespace gaia::data {

inline constexpr const char* kMirrorSuffix = "-mirror";

std::string mirrored_id(const std::string& id);       // "e1" -> "e1-mirror"
std::string mirror_source_id(const std::string& id);  // "e1-mirror" -> "e1"; any other id unchanged

// Swaps the whole words "left" and "right" (any case; "_" and other non-letters separate words, so "left_bend"
// becomes "right_bend"). "right behind" (directly behind) stays; "turn right ahead" becomes "turn left ahead".
std::string mirror_words(const std::string& text);

// A frame's labels in the mirror: signed lateral quantities (curvature, lane_offset_m) change sign and every string
// value goes through mirror_words. Lane indices stay: the whole lane layout mirrors with the picture.
nlohmann::json mirror_labels(const nlohmann::json& labels);

}  // namespace gaia::data
