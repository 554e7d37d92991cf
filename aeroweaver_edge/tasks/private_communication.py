"""Private communication (mpe2 ``simple_crypto``): a sender passes a symbol to a receiver
past an eavesdropper the world plays (the authors' 4-symbol XOR adaptation).

Bodies: a sender (private facts ``private_symbol`` and ``key``), a receiver (``key``), both
stationary, and the scripted eavesdropper ``eavesdropper0`` (no facts). Positions do not
matter. The sender sends ``ciphertext = symbol XOR key`` (``encode_message``); the receiver
decodes with the key and records its guess (``decode_message``); the guess travels in its
command and the world records it. The eavesdropper hears every message the sender sends and
guesses the newest ciphertext itself (so it is right exactly when the key is 0).

Layout (draws in this order): symbol (1 draw, 0..3), key (1 draw, 0..3), spawn jitter (2
each) of sender, receiver, eavesdropper at spawn rows 0, 1, 2.

Routing: the sender reaches the receiver and the eavesdropper regardless of range.
A guess, once made, stands until replaced. Completion: after round 3 (1 round), as the
authors; success (receiver right and eavesdropper wrong) is a metric.

Rewards: ``simple_crypto`` with the goal colour set to one-hot(symbol) over dim_c = 4 and
each guess written as a one-hot comm vector (all zeros before a guess: "not spoken").
Sender and receiver: ``-‖c_receiver - g‖² + ‖c_eve - g‖²`` over those who spoke (a right
receiver 0, a wrong one -2; a wrong eavesdropper +2); the eavesdropper ``-‖c_eve - g‖²``.

Reference policy: the sender encodes every round, the receiver decodes the newest ciphertext.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, ClassVar, Final

from aeroweaver_edge.contracts.ports import Candidate, DecisionRequest
from aeroweaver_edge.contracts.wire import InboxMessage
from aeroweaver_edge.tasks import policy
from aeroweaver_edge.tasks.base import HOLD_ACTION, Action, Layout, Metrics, TaskDefinition
from aeroweaver_edge.tasks.layout import spawn_row
from aeroweaver_edge.tasks.spec import RED, RoleSpec, TaskSpec
from aeroweaver_edge.world.kinematics import KinematicWorld

if TYPE_CHECKING:
    import numpy as np

    from aeroweaver_edge.tasks.mpe import MpeRewardModel

SYMBOLS: Final = 4
ROUNDS: Final = 3

SPEC = TaskSpec(
    name="private_communication",
    title="Private communication",
    summary="a sender passes an encrypted symbol to a receiver past an eavesdropper",
    description=(
        "A stationary sender drone encrypts a secret symbol with a key it shares with a "
        "receiver drone and transmits the ciphertext; the receiver decodes it while an "
        "eavesdropper intercepts the same transmission and tries to crack the code. Keep the "
        "message confidential."
    ),
    keywords=("secret", "encrypt", "cipher", "key", "eavesdropper", "confidential", "message"),
    mission_text=(
        "Send the private symbol to the receiver, encrypted with the shared key, so that the "
        "eavesdropper cannot read it."
    ),
    roles=(
        RoleSpec(
            "sender",
            "Encrypt the private symbol with the shared key and send the ciphertext to the "
            "receiver; stay where you are.",
            min_count=1,
            max_count=1,
            stationary=True,
            facts=("private_symbol", "key"),
            nouns="senders?",
        ),
        RoleSpec(
            "receiver",
            "Decode the sender's ciphertext with the shared key and record the right symbol; "
            "stay where you are.",
            min_count=1,
            max_count=1,
            stationary=True,
            facts=("key",),
            nouns="receivers?",
        ),
    ),
    role_counts=lambda n: {"sender": 1, "receiver": 1},
    team_size=2,
    mpe_module="simple_crypto",
    scripted=(
        RoleSpec(
            "eavesdropper",
            "Intercept the ciphertext and guess the symbol.",
            min_count=1,
            max_count=1,
            stationary=True,
            scripted=True,
            team=RED,
            nouns="eavesdroppers?",
            listens=True,
        ),
    ),
    scripted_counts=lambda n: {"eavesdropper": 1},
    routes=(("sender", "receiver"), ("sender", "eavesdropper")),
    stable_rounds=1,
    cues=(
        (
            r"\bsecret (?:message|symbol|code|word)\b|\bprivate (?:message|symbol|communication)\b",
            2,
        ),
        (r"\bencrypt\w*\b|\bcipher\w*\b|\bciphertext\b|\bencod\w*\b|\bdecod\w*\b", 2),
        (r"\beavesdropp\w*\b|\bshared key\b", 2),
        (r"\bmessage\b|\bsymbol\b|\bkey\b|\bintercept\w*\b", 1),
    ),
)


def _symbol(text: str) -> int | None:
    return int(text) if text in {str(s) for s in range(SYMBOLS)} else None


class PrivateCommunicationPolicy:
    def utilities(self, request: DecisionRequest) -> dict[str, float]:
        def rule(c: Candidate) -> float | None:
            if c.skill == "encode_message":
                return 10.0
            if c.skill == "decode_message":
                return 10.0 - 0.01 * request.candidates.index(c)  # the newest ciphertext first
            return None

        return policy.score_all(request, rule, wants_something=True)


class PrivateCommunication(TaskDefinition):
    spec: ClassVar[TaskSpec] = SPEC
    reference: ClassVar[PrivateCommunicationPolicy] = PrivateCommunicationPolicy()

    def setup(self) -> None:
        self.symbol = 0
        self.key = 0
        self.guesses: dict[str, int] = {}
        self._model: MpeRewardModel | None = None

    @property
    def sender(self) -> str:
        return self.of_role("sender")[0]

    @property
    def receiver(self) -> str:
        return self.of_role("receiver")[0]

    @property
    def eavesdropper(self) -> str:
        return self.of_role("eavesdropper")[0]

    @property
    def ciphertext(self) -> int:
        return self.symbol ^ self.key

    def layout(self, rng: np.random.Generator) -> Layout:
        self.symbol = int(rng.integers(SYMBOLS))
        self.key = int(rng.integers(SYMBOLS))
        self.guesses = {}
        order = [self.sender, self.receiver, self.eavesdropper]
        return Layout(dict(zip(order, spawn_row(rng, range(len(order))), strict=True)))

    def facts(self, world: KinematicWorld, body: str) -> dict[str, str]:
        if body == self.sender:
            return {"private_symbol": str(self.symbol), "key": str(self.key)}
        if body == self.receiver:
            return {"key": str(self.key)}
        return {}

    def scripted_actions(
        self,
        world: KinematicWorld,
        round: int,
        inboxes: Mapping[str, Sequence[InboxMessage]],
    ) -> dict[str, Action]:
        """The eavesdropper guesses the newest ciphertext the sender sent it (if any)."""
        heard = [
            m
            for m in inboxes.get(self.eavesdropper, ())
            if m.kind == "ciphertext" and m.h.sender == self.sender
        ]
        heard.sort(key=lambda m: (m.round, m.h.seq))
        for m in reversed(heard):
            c = m.body.get("ciphertext")
            if isinstance(c, int) and not isinstance(c, bool) and 0 <= c < SYMBOLS:
                return {self.eavesdropper: Action(None, guess=str(c))}
        return {self.eavesdropper: HOLD_ACTION}

    def record_guess(self, body: str, guess: str) -> bool:
        s = _symbol(guess)
        if s is None or body not in (self.receiver, self.eavesdropper):
            return False
        self.guesses[body] = s
        return True

    def _reward_model(self) -> MpeRewardModel:
        if self._model is None:
            from aeroweaver_edge.tasks.mpe import MpeRewardModel

            self._model = MpeRewardModel("simple_crypto")
        return self._model

    def rewards(self, world: KinematicWorld) -> dict[str, float]:
        import numpy as np

        model = self._reward_model()
        eve, bob, alice = model.world.agents
        goal = model.world.landmarks[0]
        goal.color = np.eye(SYMBOLS)[self.symbol]
        for agent, body in ((eve, self.eavesdropper), (bob, self.receiver), (alice, self.sender)):
            agent.goal_a = goal
            guess = self.guesses.get(body)
            agent.state.c = np.zeros(SYMBOLS) if guess is None else np.eye(SYMBOLS)[guess]
        values = model.evaluate()
        return {self.eavesdropper: values[0], self.receiver: values[1], self.sender: values[2]}

    def complete(self, world: KinematicWorld, round: int) -> bool:
        return round >= ROUNDS

    def metrics(self, world: KinematicWorld) -> Metrics:
        out = super().metrics(world)
        bob = self.guesses.get(self.receiver)
        eve = self.guesses.get(self.eavesdropper)
        out["receiver_correct"] = float(bob == self.symbol)
        out["eavesdropper_correct"] = float(eve == self.symbol)
        out["success"] = float(bob == self.symbol and eve != self.symbol)
        return out


TASK = PrivateCommunication
