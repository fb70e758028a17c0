// The files of a run, level by level, as both drivers write them:
//   curve.csv      one row per level, its values given by column name (a
//                  restart first replays the rows of its checkpoint);
//   levels.h5      the state of every level (output.hpp) and levels.xdmf
//                  beside it (xdmf.hpp); a new run removes an old file, a
//                  restart truncates it to the levels of its checkpoint;
//   checkpoint.h5  after every level (and where a driver asks, inside one):
//                  what -restart needs (checkpoint.hpp).
#pragma once
#include <map>
#include <string>
#include <vector>

#include "deformix/checkpoint.hpp"
#include "deformix/output.hpp"
#include "deformix/problem.hpp"

namespace deformix {

class LevelOutputs {
 public:
  struct Files {
    std::string dir;                 // output directory
    bool hdf5 = true;                // levels.h5 and levels.xdmf
    bool checkpoint = true;          // checkpoint.h5
    bool checkpoint_levels = false;  // checkpoint_level_<k>.h5 of every level k
  };
  // Opens curve.csv with `columns`; restart: the checkpoint being continued
  // (nullptr for a new run).
  PetscErrorCode Open(MPI_Comm comm, const Files &files, const std::vector<std::string> &columns,
                      const Checkpoint *restart);
  // Levels already in the curve (those of the checkpoint being continued).
  size_t LevelsDone() const { return rows_.size(); }
  // Writes level `level` (P/E = pressures[level]) just solved: its curve row,
  // which must name every column and nothing else, its state in levels.h5,
  // and the checkpoint, which `c` describes (driver, scene, packing, values)
  // and which is completed with the curve, the load step and the state
  // (checkpoint.h5, and checkpoint_level_<level>.h5 with checkpoint_levels).
  PetscErrorCode Level(size_t level, const std::vector<double> &pressures, const std::map<std::string, double> &row,
                       double load_step, const CompactionProblem &problem, Checkpoint c);
  // A checkpoint inside level LevelsDone() (compact: after its frictionless
  // settling), with `state` and `c` as for Level; nothing else is written.
  PetscErrorCode MidLevelCheckpoint(const std::vector<double> &pressures, double load_step,
                                    const CompactionProblem::Snapshot &state, Checkpoint c);
  // Where the checkpoints go ("" with checkpoints off).
  std::string CheckpointPath() const { return files_.checkpoint ? files_.dir + "/checkpoint.h5" : ""; }
  // checkpoint_level_<level>.h5 in the output directory.
  std::string LevelCheckpointPath(size_t level) const;
  // "curve.csv, levels.h5, checkpoint.h5": what the run writes.
  std::string Written() const;

 private:
  MPI_Comm comm_ = MPI_COMM_NULL;
  Files files_;
  std::vector<std::string> columns_;
  std::vector<std::vector<double>> rows_;
  CsvWriter curve_;
};

}  // namespace deformix
