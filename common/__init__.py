"""What the services share, in rooms by who uses them; importing ``common`` itself loads nothing.

``common.client`` is what any trainer needs to take its tasks from a teacher service (the API schemas
the service shares too), ``common.kuka`` the KUKA grasp environments, and ``common.policy`` what the
rollout workers and the learner exchange.
"""
