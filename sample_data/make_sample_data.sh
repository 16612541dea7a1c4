#!/usr/bin/env bash
# Regenerate the sample recordings from their configs (run from the repository root):
# the excitation of configs/stage_design.yaml played into the "machine" configs/stage_true.yaml.
set -euo pipefail
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
nlsid -q design configs/stage_design.yaml -o "$tmp/excitation.h5"
nlsid -q simulate configs/stage_true.yaml --excitation "$tmp/excitation.h5" -o sample_data/stage.h5 --force
nlsid -q simulate configs/stage_true.yaml --excitation "$tmp/excitation.h5" -o sample_data/stage.mcap --force
