// The element types of the compiled engine, by the key of their Python module
// (se3dyn.elements.<key>): adding an element type is its header here and its Python module.
#pragma once
#include <memory>
#include <stdexcept>
#include <string>

#include "beam.hpp"
#include "body.hpp"
#include "joint.hpp"
#include "joint_force.hpp"
#include "load.hpp"
#include "spring_damper.hpp"
#include "bushing.hpp"
#include "contact.hpp"

namespace se3dyn {

inline std::unique_ptr<ElementBatch> make_batch(const std::string& key) {
  if (key == "body") return std::make_unique<Bodies>();
  if (key == "joint") return std::make_unique<Joints>();
  if (key == "joint_force") return std::make_unique<JointForces>();
  if (key == "load") return std::make_unique<Loads>();
  if (key == "spring_damper") return std::make_unique<SpringDampers>();
  if (key == "bushing") return std::make_unique<Bushings>();
  if (key == "beam") return std::make_unique<Beams>();
  if (key == "contact") return std::make_unique<Contacts>();
  throw std::invalid_argument("no compiled kernel for the element type '" + key + "'");
}

}  // namespace se3dyn
