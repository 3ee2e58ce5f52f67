#pragma once
// A folder of clips with a manifest (`gaia ingest DIR --manifest clips.csv`): one CSV row per clip, whose columns
// become the episode's metadata and caption.
//
//   file            the clip, relative to the clips' folder (required; a video file, GIF or image folder)
//   fps             a stated frame rate: used where the container states none, or states another (the clip is then
//                   timed by frame index at this rate)
//   weather         clear | overcast | rain | fog | snow        (the procedural world's values; "" = unknown)
//   time_of_day     day | dusk | night
//   road            city | highway | rural | residential | parking | tunnel
//   source_repo     where the clip comes from: clips of one source share a driver and often a road, so held-out
//                   sets are chosen by it (gaia data split --hold-out-by source_repo)
//   place, licence, notes and any other column: kept as metadata, as they are
//
// Unknown values of weather, time_of_day and road are errors naming the clip and the column, so that a typo never
// becomes a condition of its own.
#include <map>
#include <string>
#include <vector>

#include "gaia/core/fs.h"

namespace gaia::data {

struct ManifestRow {
  int line = 0;                                // line in the manifest (for messages)
  std::string file;                            // as written
  fs::path path;                               // resolved against the clips' folder
  std::string id;                              // episode id: the file name without its extension
  double fps = 0;                              // 0 = none stated
  std::map<std::string, std::string> columns;  // every other non-empty cell, by column name
  std::string weather() const { return get("weather"); }
  std::string time_of_day() const { return get("time_of_day"); }
  std::string road() const { return get("road"); }
  std::string get(const std::string& column) const {
    auto it = columns.find(column);
    return it == columns.end() ? "" : it->second;
  }
};

struct Manifest {
  fs::path file;
  std::vector<std::string> header;
  std::vector<ManifestRow> rows;
};

const std::vector<std::string>& manifest_values(const std::string& column);  // the accepted values; {} = any

// Reads and checks the whole manifest before anything is ingested: the header (a `file` column), each row's cell
// count, fps, the values of weather / time_of_day / road, and duplicate ids. A clip file that is missing is not an
// error here (ingest reports it by name and goes on with the others).
// `clips`: the folder the file names are relative to.
Manifest read_manifest(const fs::path& csv, const fs::path& clips);
// Where `--manifest csv` is: the path as given, else (a relative one) inside the folder of clips.
fs::path find_manifest(const fs::path& csv, const fs::path& clips);

// The caption of a clip's frame at `time_s`: its conditions phrase (worded as the procedural world's captions, the
// wording varying from second to second) and its road, e.g. "rainy day, on a highway".
std::string manifest_caption(const ManifestRow& row, double time_s);

}  // namespace gaia::data
