"""What keeps a UAV inside its envelope and the operator in charge: the safety gate every
motion passes, the approval gate for vehicle actions and its mesh link, and what an
operator may send over the mesh."""
