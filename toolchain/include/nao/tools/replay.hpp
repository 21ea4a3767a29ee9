// Replay of a recording into camera folders (nao_toolchain replay): a recording's OpenPose
// frames (its cam0/, cam1/, ... folders, as synth writes them) written into live camera folders
// at the capture rate, the way OpenPose --write_json writes them: a plain file (open, a few
// write calls, close), never renamed into place, so a reader may see it half written. The
// stand-in for a camera rig when nao_rt's live camera source is tested.
//
// Faults for tests (ReplayFaults; from the command line through the environment variable
// NAO_REPLAY_FAULTS, docs/formats.md "Replay"): truncated frames that never complete, frames
// with nobody in them, a camera folder removed for a while, a camera that stops.
#pragma once

#include <string>
#include <vector>

namespace nao::tools {

struct ReplayFaults {
  long long truncate_every = 0;     ///< every N-th frame index one camera (in turn) writes half its file; 0: none
  long long no_person_every = 0;    ///< every N-th frame index every camera writes {"people": []}; 0: none
  double remove_folder_at_s = -1.0; ///< replay time the fault camera's folder is removed with its files; < 0: never
  double remove_for_s = 1.0;        ///< ... and made again this much later (frames due meanwhile are lost)
  double stop_at_s = -1.0;          ///< replay time from which the fault camera writes nothing; < 0: never
  int fault_camera = 0;             ///< camera of remove_folder_at_s and stop_at_s
};

/// NAO_REPLAY_FAULTS text (comma-separated key=value: truncate_every, no_person_every,
/// remove_folder_at, remove_for, stop_at, fault_camera) -> faults; empty or null text: none.
/// Throws UserError naming the variable and the bad item.
ReplayFaults parseReplayFaults(const char* text, int n_cameras);

struct ReplayOptions {
  std::string recording;             ///< folder with cam0/, cam1/, ...
  std::vector<std::string> targets;  ///< one folder per camera, made when its first frame is written
  double fps = 30.0;                 ///< capture rate of the recording, Hz
  double speed = 1.0;                ///< replay speed factor
  int chunks = 3;                    ///< write calls per file
  ReplayFaults faults;
};

struct ReplayReport {
  int n_indices = 0;   ///< frame indices replayed
  int n_files = 0;     ///< files written (whole, truncated or empty)
  int n_truncated = 0;
  int n_no_person = 0;
  int n_lost = 0;      ///< files not written (folder away, camera stopped)
};

/// Plays the recording (frame index i at (i - first) / (fps * speed) s after the start, paced on
/// CLOCK_MONOTONIC absolute deadlines) and returns after the last frame. Throws UserError for a
/// recording without camera folders or frames, a folder count that differs from the targets',
/// or a file that cannot be written.
ReplayReport replayRecording(const ReplayOptions& options);

}  // namespace nao::tools
