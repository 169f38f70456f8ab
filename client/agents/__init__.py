"""Controllers of the ego vehicle: DDPG (torch), an IDM follower, a random policy."""
