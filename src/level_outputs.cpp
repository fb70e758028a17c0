#include "deformix/level_outputs.hpp"

#include <cstdio>

#include "deformix/xdmf.hpp"

namespace deformix {

PetscErrorCode LevelOutputs::Open(MPI_Comm comm, const Files &files, const std::vector<std::string> &columns,
                                  const Checkpoint *restart) {
  PetscFunctionBeginUser;
  comm_ = comm, files_ = files, columns_ = columns;
  PetscCall(curve_.Open(comm, files.dir + "/curve.csv", columns));
  rows_ = restart ? restart->rows : std::vector<std::vector<double>>();
  for (const std::vector<double> &row : rows_) PetscCall(curve_.Row(row));
  // Results of an earlier run in this directory must not mix with this one;
  // a restarted run keeps the levels before its checkpoint.
  const std::string h5 = files.dir + "/levels.h5";
  if (restart) {
    PetscCall(TruncateLevelsHDF5(comm, h5, static_cast<int>(rows_.size())));
  } else {
    PetscCall(RemoveFile(comm, h5));
    PetscCall(RemoveFile(comm, XdmfPathOf(h5)));
  }
  // Nor may its level checkpoints beyond this run's start: an earlier run wrote
  // them from some level on without gaps.
  if (files.checkpoint_levels) {
    PetscMPIInt rank;
    PetscCallMPI(MPI_Comm_rank(comm, &rank));
    if (rank == 0)
      for (size_t k = rows_.size(); std::remove(LevelCheckpointPath(k).c_str()) == 0; ++k) {
      }
  }
  PetscFunctionReturn(0);
}

PetscErrorCode LevelOutputs::Level(size_t level, const std::vector<double> &pressures,
                                   const std::map<std::string, double> &row, double load_step,
                                   const CompactionProblem &problem, Checkpoint c) {
  PetscFunctionBeginUser;
  std::vector<double> values;
  for (const std::string &name : columns_) {
    const auto it = row.find(name);
    PetscCheck(it != row.end(), comm_, PETSC_ERR_PLIB, "curve.csv row without a value for column %s", name.c_str());
    values.push_back(it->second);
  }
  PetscCheck(row.size() == columns_.size(), comm_, PETSC_ERR_PLIB, "curve.csv row names %zu values for %zu columns",
             row.size(), columns_.size());
  rows_.push_back(values);
  PetscCall(curve_.Row(values));
  if (files_.hdf5) PetscCall(WriteLevelHDF5(comm_, files_.dir + "/levels.h5", static_cast<int>(level), pressures[level], problem));
  if (files_.checkpoint || files_.checkpoint_levels) {
    // One snapshot (WriteLevelCheckpoint completes c), written to
    // checkpoint.h5 and/or the level's own file.
    c.columns = columns_;
    const std::string level_path = LevelCheckpointPath(level);
    PetscCall(WriteLevelCheckpoint(comm_, files_.checkpoint ? files_.dir + "/checkpoint.h5" : level_path, pressures, level,
                                   rows_, load_step, problem, &c));
    if (files_.checkpoint && files_.checkpoint_levels) PetscCall(WriteCheckpoint(comm_, level_path, c));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode LevelOutputs::MidLevelCheckpoint(const std::vector<double> &pressures, double load_step,
                                                const CompactionProblem::Snapshot &state, Checkpoint c) {
  PetscFunctionBeginUser;
  if (!files_.checkpoint) PetscFunctionReturn(0);
  c.columns = columns_;
  c.rows = rows_;
  c.levels.assign(pressures.begin(), pressures.begin() + rows_.size());
  c.load_step = load_step;
  c.state = state;
  PetscCall(WriteCheckpoint(comm_, CheckpointPath(), c));
  PetscFunctionReturn(0);
}

std::string LevelOutputs::LevelCheckpointPath(size_t level) const {
  char name[48];
  std::snprintf(name, sizeof(name), "/checkpoint_level_%04zu.h5", level);
  return files_.dir + name;
}

std::string LevelOutputs::Written() const {
  return "curve.csv" + std::string(files_.hdf5 ? ", levels.h5, levels.xdmf" : "") +
         (files_.checkpoint ? ", checkpoint.h5" : "") + (files_.checkpoint_levels ? ", checkpoint_level_*.h5" : "");
}

}  // namespace deformix
