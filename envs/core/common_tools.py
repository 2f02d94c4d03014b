"""Tools every domain has: `think` (reasoning scratchpad) and `submit_answer` (ends the episode)."""

from __future__ import annotations

from envs.core.tools import Toolkit, ToolType, is_tool


class BaseDomainTools(Toolkit):
    """Domain toolkits subclass this to inherit `think` and `submit_answer`."""

    @is_tool(ToolType.THINK)
    def think(self, thought: str) -> str:
        """Record a reasoning step; it has no effect on the patient or the record.

        Args:
            thought: Your reasoning, in plain text.
        """
        return "Thought recorded."

    @is_tool(ToolType.GENERIC, submit=True)
    def submit_answer(self, answer: str, reasoning: str = "") -> str:
        """Submit your final answer and end the episode.

        Args:
            answer: The final answer: an option letter for multiple-choice questions, otherwise the
                requested value, category or recommendation.
            reasoning: A short justification of the answer.
        """
        return f"Answer submitted: {answer}"
