"""Every file format and the checks on what is read: markers.json, calibration.json and TOML
(calibfile), result.json, init.json and the result of an initialization (initfile), BVH and
ASF/AMC captures (bvh, amc), the CMU database's skeletons, captures and manifests (cmu), safe
reading and atomic writing (inputs, outputs), plausibility of inputs that parse (plausible). May
import core.geometry, core.body and core.imaging.
"""
