# Environment for HRI Physio: source this file (scripts do it for you).
# ROS 2 comes from pip wheels inside .venv; the ament index lives there too.
_hri_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export HRI_PHYSIO_ROOT="$_hri_root"
export VIRTUAL_ENV="$_hri_root/.venv"
export PATH="$VIRTUAL_ENV/bin:$PATH"
export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
# Health data stays on this machine unless a lab explicitly widens discovery.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export LSLAPICFG="${LSLAPICFG:-$_hri_root/config/lsl_api.cfg}"
export PYTHONUNBUFFERED=1
unset _hri_root
