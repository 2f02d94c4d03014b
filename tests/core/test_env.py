import json
import pickle

import gymnasium
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import envs
from envs import registry
from envs.env import HealthcareGymEnv
from envs.core.trajectory import read_trajectories, write_trajectories


def call(name, **arguments):
    return "<tool_call>" + json.dumps({"name": name, "arguments": arguments}) + "</tool_call>"


def test_registered_and_kwargs():
    env = gymnasium.make("HealthcareGym-v0", domain="ward", split="test", max_turns=3)
    assert [t.id for t in env.unwrapped.tasks] == ["ward_choice"]
    obs, info = env.reset(seed=1)
    assert info["task_id"] == "ward_choice" and info["domain"] == "ward" and info["max_turns"] == 3
    assert {t["function"]["name"] for t in info["tools"]} >= {"get_patient", "submit_answer", "count_patients"}
    assert "Ward policy" in obs and "Which drug class" in obs and "B. Penicillins" in obs
    assert info["policy"].startswith("# Ward policy")
    env.close()


@pytest.mark.parametrize("domain", registry.list_domains())
def test_check_env_every_registered_domain(domain):
    env = gymnasium.make("HealthcareGym-v0", domain=domain, max_turns=4)
    check_env(env.unwrapped, skip_render_check=True)


def test_spaces_contain_everything_and_pickle_small():
    env = HealthcareGymEnv(domain="ward")
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    for text in ["", "multi\nline", '{"json": [1, 2]}', "ünïcødé 🩺 中文", "\x00\t"]:
        assert env.action_space.contains(text)
    assert not env.action_space.contains(b"bytes") and not env.action_space.contains(None)
    assert len(pickle.dumps(env.observation_space)) < 10_000
    assert len(pickle.dumps(env.action_space)) < 10_000


def test_reset_is_deterministic_under_seed():
    env = HealthcareGymEnv(domain="ward")
    picks = [env.reset(seed=s)[1]["task_id"] for s in range(10)]
    again = [env.reset(seed=s)[1]["task_id"] for s in range(10)]
    assert picks == again and len(set(picks)) > 1
    _, info = env.reset(seed=3, options={"task_id": "ward_dose"})
    assert info["task_id"] == "ward_dose"
    with pytest.raises(KeyError, match="nope"):
        env.reset(options={"task_id": "nope"})


def test_gold_episode_terminates_with_reward_components(ward_env):
    ward_env.reset(seed=0, options={"task_id": "ward_choice"})
    obs, reward, terminated, truncated, info = ward_env.step(call("get_patient", patient_id="P1"))
    assert reward == 0.0 and not terminated and "penicillin" in obs
    obs, reward, terminated, truncated, info = ward_env.step(call("submit_answer", answer="B"))
    assert terminated and not truncated
    comps = info["reward_components"]
    assert comps["accuracy"] == pytest.approx(1.0)
    assert reward == pytest.approx(comps["total"]) and reward > 0.5
    assert info["is_correct"] is True
    wrong = HealthcareGymEnv(domain="ward", task_id="ward_choice")
    wrong.reset(seed=0)
    wrong.step(call("get_patient", patient_id="P1"))
    _, wrong_reward, *_ , wrong_info = wrong.step(call("submit_answer", answer="A"))
    assert wrong_info["reward_components"]["accuracy"] == 0.0 and wrong_reward < reward


def test_truncation_at_max_turns():
    env = HealthcareGymEnv(domain="ward", task_id="ward_choice", max_turns=2)
    env.reset(seed=0)
    _, _, terminated, truncated, _ = env.step("thinking out loud")
    assert not terminated and not truncated
    _, reward, terminated, truncated, info = env.step("still thinking")
    assert truncated and not terminated and "reward_components" in info
    obs, reward, terminated, *_ = env.step("after the end")
    assert "episode is over" in obs and reward == 0.0


def test_several_calls_in_one_action_run_in_order(ward_env):
    ward_env.reset(seed=0, options={"task_id": "ward_record"})
    obs, *_ = ward_env.step(call("add_allergy", patient_id="P2", substance="latex") + call("get_patient", patient_id="P2"))
    assert obs.index("[add_allergy]") < obs.index("[get_patient]") and '"latex"' in obs


def test_write_changes_db_hash_and_failed_write_does_not(ward_env):
    ward_env.reset(seed=0, options={"task_id": "ward_record"})
    h0 = ward_env.domain_env.db_hash()
    obs, *_ = ward_env.step(call("add_allergy", patient_id="P2", substance="forbidden", severity="severe"))
    assert "error" in obs and ward_env.domain_env.db_hash() == h0
    ward_env.step(call("add_allergy", patient_id="P2", substance="latex"))
    _, _, terminated, _, info = ward_env.step(call("submit_answer", answer="recorded"))
    traj = info["trajectory"]
    assert traj.db_hash_initial == h0 and traj.db_hash_final != h0


def test_errors_are_observations(ward_env):
    ward_env.reset(seed=0, options={"task_id": "ward_dose"})
    obs, *_ = ward_env.step(call("get_patiant", patient_id="P1"))
    assert "unknown tool" in obs and "get_patient" in obs
    obs, *_ = ward_env.step(call("dose_for_weight", patient_id="P2", mg_per_kg="fifteen"))
    assert "'mg_per_kg'" in obs and "number" in obs
    obs, *_ = ward_env.step(call("get_patient", patient_id="P9"))
    assert "not found" in obs and "P1" in obs


def test_render_ansi_and_human(ward_env, capsys):
    ward_env.reset(seed=0, options={"task_id": "ward_choice"})
    ward_env.step(call("get_patient", patient_id="P1"))
    text = ward_env.render()
    assert "[call] get_patient" in text and "Ana Ruiz" in text
    human = HealthcareGymEnv(domain="ward", task_id="ward_choice", render_mode="human")
    human.reset(seed=0)
    human.step(call("get_patient", patient_id="P1"))
    assert "[call] get_patient" in capsys.readouterr().out


def test_trajectory_parquet_round_trip(tmp_path, ward_env):
    records = []
    for task_id, answer in (("ward_choice", "B"), ("ward_dose", "375 mg")):
        ward_env.reset(seed=7, options={"task_id": task_id})
        ward_env.step("Let me think. " + call("think", thought="weight-based"))
        ward_env.step(call("submit_answer", answer=answer))
        records.append(ward_env.trajectory())
    path = tmp_path / "episodes.parquet"
    write_trajectories(records, path)
    back = read_trajectories(path)
    assert [r.model_dump() for r in back] == [r.model_dump() for r in records]
    assert back[0].turns[0].tool_calls[0].name == "think" and back[0].turns[0].duration_s > 0
    assert back[1].reward_components and back[1].submitted_answer == "375 mg"


def test_vector_envs():
    fns = [lambda: HealthcareGymEnv(domain="ward", max_turns=3) for _ in range(2)]
    sync = gymnasium.vector.SyncVectorEnv(fns)
    obs, info = sync.reset(seed=[0, 1])
    assert len(obs) == 2 and all(isinstance(o, str) for o in obs)
    obs, rewards, term, trunc, info = sync.step(["hello", call("think", thought="x")])
    assert len(rewards) == 2
    sync.close()
    asyn = gymnasium.vector.AsyncVectorEnv(fns, shared_memory=False)
    obs, info = asyn.reset(seed=[0, 1])
    obs, rewards, term, trunc, info = asyn.step([call("submit_answer", answer="B"), "text"])
    assert len(obs) == 2 and term[0]
    asyn.close()


_structured = st.one_of(
    st.text(max_size=200),
    st.builds(lambda n, a: json.dumps({"name": n, "arguments": a}),
              st.one_of(st.text(max_size=20), st.sampled_from(["get_patient", "add_allergy", "dose_for_weight", "submit_answer"])),
              st.one_of(st.dictionaries(st.text(max_size=10), st.one_of(st.none(), st.integers(), st.floats(), st.text(max_size=10), st.lists(st.integers(), max_size=3)), max_size=4),
                        st.text(max_size=20), st.integers(), st.none())),
    st.builds(lambda body: f"<tool_call>{body}</tool_call>", st.text(max_size=80)),
    st.builds(lambda body: f"```json\n{body}\n```", st.text(max_size=80)),
    st.builds(lambda n, body: f"{n}({body})", st.sampled_from(["get_patient", "add_allergy", "dose_for_weight", "think"]), st.text(max_size=60)),
    st.builds(lambda body: json.dumps({"type": "function", "function": {"name": "add_allergy", "arguments": body}}), st.text(max_size=60)),
)


@settings(max_examples=10_000, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(action=_structured)
def test_fuzz_malformed_actions_never_raise_and_failed_calls_change_nothing(action):
    env = _FUZZ_ENV
    env.reset(seed=0, options={"task_id": "ward_record"})
    before = env.domain_env.db_hash()
    obs, reward, terminated, truncated, info = env.step(action)
    assert env.observation_space.contains(obs)
    record = env.trajectory().turns[-1]
    if all(not c.ok for c in record.tool_calls) or not record.tool_calls:
        assert env.domain_env.db_hash() == before


_FUZZ_ENV = HealthcareGymEnv(domain="ward", max_turns=50)


def test_image_tasks_give_an_image_content_part():
    env = HealthcareGymEnv(domain="ward")
    task = env._tasks_by_id["ward_choice"].model_copy(update={"image_path": "/data/cxr_001.png"})
    env._tasks_by_id["ward_choice"] = task
    obs, info = env.reset(seed=0, options={"task_id": "ward_choice"})
    assert "[image: /data/cxr_001.png]" in obs and info["image_path"] == "/data/cxr_001.png"
    record = env.trajectory()
    assert record.image_path == "/data/cxr_001.png"
    assert record.messages[1]["content"][0] == {"type": "image", "image": "/data/cxr_001.png"}
    assert "[image: /data/cxr_001.png]" in env.transcript()


def test_env_records_the_error_kind_of_each_call():
    env = HealthcareGymEnv(domain="ward")
    env.reset(seed=0)
    env.step(call("get_patient", patient_id="nobody") + call("no_such_tool") + call("count_patients"))
    calls = env.trajectory().turns[-1].tool_calls
    assert [c.error_kind for c in calls] == ["tool_error", "unknown_tool", None]
