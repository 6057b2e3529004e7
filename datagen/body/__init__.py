"""A robot's body: its record, the MuJoCo model built from it, kinematics, camera and what it sees."""
