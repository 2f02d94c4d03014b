"""Knowledge-base benchmark: our KB vs SQLite FTS5 (the paper's design), tantivy and bm25s.

    python bench/kb.py                          # the paper's size: 828,473 passages, 1,000 queries
    python bench/kb.py --n-passages 50000       # a quick run

A seeded generator writes a synthetic medical corpus (60-250 words per passage: Zipf-distributed
English, a few thousand generated medical terms clustered by topic, and a rare-token tail) and
1,000 queries of 3-12 words. Each engine is built in its own process (build time, peak RSS of
that process, size on disk) and queried by 1 and then 2 processes (top-10, single-threaded per
process): p50/p99 latency, queries/s, and overlap@10 with bm25s. All engines rank with BM25
(k1=1.2, b=0.75) over an OR of the query's distinct words with English stop words dropped:

* ours     -- kb_service.KnowledgeBase.search (bm25s kernel + SQLite passages + highlighted
              snippets: the full call an agent tool makes)
* ours-rank -- kb_service.KnowledgeBase.rank on the same index: the ranking alone (query
              analysis, filters, bm25s kernel), doc ids mapped from memory like the bm25s row
* fts5     -- SQLite FTS5, the paper's table and tokenizer, `MATCH` of quoted OR-ed words,
              `ORDER BY bm25()` (the safe query builder); timed on a seeded sample of queries
* tantivy  -- tantivy-py, English stemming, stored text, boolean OR of term queries
* bm25s    -- bm25s with its own tokenizer (English stop words), numba backend

Results go to stdout (a markdown table and target checks) and to <workdir>/results-<n>.json.

Scaling (the cost of growing the KB toward PubMed's 24M passages):

    nice -n 10 python bench/kb.py --profile pubmed --n-passages 100000,1000000 \
        --engines ours,ours-rank,bm25s,tantivy --memory-budget-mb 2048 --procs 1

`--profile pubmed` draws passages of MedRAG's PubMed snippet length from a Zipf vocabulary
(`PubMedGenerator`, parameters and sources above it); `--n-passages` takes several sizes, each
built and queried in turn, then one table with every engine's build time, build peak RSS, size,
p50/p99 and q/s and its q/s ratio to bm25s at the same size. `--memory-budget-mb` builds ours as
a sharded index within that budget; the peers' build processes run under an address-space cap
(available memory less 2 GB) so that one that needs more fails alone and is reported as failed.

Workers (`hcgym kb build --workers`): `--kb-workers 1,2` builds ours once per number of worker
processes listed, one after the other on one corpus, and reports build time, CPU time (user +
system of the build and its workers, from wait4), peak RSS (wait4: the largest process) and the
build's own account of each process's peak; no queries.
"""

from __future__ import annotations

import argparse
import gzip
import json
import multiprocessing as mp
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

PAPER_N = 828_473
K = 10
STOPWORDS = {"a", "an", "and", "are", "as", "at", "be", "but", "by", "for", "if", "in", "into", "is", "it", "no",
             "not", "of", "on", "or", "such", "that", "the", "their", "then", "there", "these", "they", "this",
             "to", "was", "will", "with"}

# ---------------------------------------------------------------------------------------------
# Synthetic corpus
# ---------------------------------------------------------------------------------------------

COMMON_ENGLISH = """the of and to a in is that for it as was with be by on not he this are or his from at which
but have an they you were her she there been one all we their has would when if so can no more out up what
its about into than them only other time new some could these two may first then do any like my now over
such our man me even most made after also did many before must through back years where much your way well
down should because each just those people how too little state good very make world still own see men work
long get here between both life being under never day same another know while last might us great old year
off come since against go came right used take three states himself few house use during without again place
around however home small found thought went say part once general high upon school every does got united left
number course war until always away something fact though water less public put think almost hand enough far
took head yet government system better set told nothing night end why called didn't eyes find going look asked
later knew point next program city business give group toward young days let room president side social given
present several order national possible rather second face per among form important often things looked early
white case john become large big need four within felt along children saw best church ever least power development
light thing family interest want members mind country area others done turned although open god service certain
kind problem began different door thus help means sense whole matter perhaps itself york times law human line above
name example action company hands local show whether five history gave today either act feet across taken past
quite anything seen having death week experience body word half really field am car words already themselves
information tell together college shall money period held keep sure probably free seems real behind cannot miss
political air question making office brought whose special heard major problems ago became federal study available
known result street economic boy position reason change south board individual job areas society west close turn
love community true court force full seem am policy process patient patients clinical treatment dose therapy
risk blood pain test level levels rate normal acute chronic disease care daily hospital""".split()

# Pseudo-words are consonant-vowel syllables ending in a, o or u: no English stemmer changes
# them, so every engine sees the same vocabulary whatever its stemming (a fair comparison).
SYLLABLES = ("ba be bi bo bu ca ce ci co cu da de di do du fa fe fi fo fu ga ge gi go gu ha he hi ho hu ja je ji "
             "jo ju ka ke ki ko ku la le li lo lu ma me mi mo mu na ne ni no nu pa pe pi po pu ra re ri ro ru sa "
             "se si so su ta te ti to tu va ve vi vo vu wa we wi wo za ze zi zo zu bra cre dri flo gru pla sto "
             "tri").split()
FINAL_SYLLABLES = [s for s in SYLLABLES if s[-1] in "aou"]

MED_ROOTS = ("cardi hepat nephr neur gastr pulmon derm oste arthr my hemat lymph angi encephal mening thyr aden "
             "cyst col rect esophag pancreat splen ur pyel ren cholecyst chondr fibr lip leuk erythr thromb vas "
             "phleb bronch trache laryng pharyng rhin ot ophthalm retin kerat blephar gingiv gloss stomat sial "
             "mast metr salping oophor orchi prostat vesic hyster cephal crani spondyl myel radicul tendin "
             "ten burs synov glomerul tubul cortic adren pituit gonad ovar placent amni fet sarc carcin melan").split()
MED_SUFFIXES = ("itis opathy algia ectomy otomy ostomy oma osis emia uria plasty scopy graphy megaly penia cytosis "
                "rrhea rrhage sclerosis stenosis trophy plasia genesis lysis").split()
MED_PREFIXES = "hyper hypo peri endo epi intra sub poly dys neo".split()
MED_TERMS = ("warfarin heparin apixaban rivaroxaban metformin insulin lisinopril amlodipine metoprolol atorvastatin "
             "simvastatin aspirin clopidogrel ibuprofen naproxen acetaminophen morphine fentanyl oxycodone "
             "amoxicillin ceftriaxone vancomycin azithromycin doxycycline ciprofloxacin levofloxacin prednisone "
             "dexamethasone hydrocortisone levothyroxine furosemide spironolactone hydrochlorothiazide digoxin "
             "amiodarone diltiazem verapamil sertraline fluoxetine citalopram lithium haloperidol quetiapine "
             "olanzapine lorazepam diazepam midazolam propofol ketamine epinephrine norepinephrine dopamine "
             "sepsis pneumonia asthma diabetes hypertension hypotension tachycardia bradycardia fibrillation "
             "infarction ischemia stroke embolism thrombosis anemia leukemia lymphoma melanoma carcinoma "
             "adenocarcinoma metastasis dyspnea orthopnea edema ascites jaundice cirrhosis hepatitis "
             "pancreatitis appendicitis cholecystitis diverticulitis colitis gastroenteritis meningitis "
             "encephalitis seizure epilepsy migraine dementia delirium depression anxiety schizophrenia "
             "troponin creatinine bilirubin albumin lactate procalcitonin ferritin hemoglobin platelet "
             "neutrophil lymphocyte potassium sodium magnesium calcium phosphate bicarbonate glucose "
             "echocardiogram electrocardiogram tomography ultrasound radiograph biopsy endoscopy colonoscopy "
             "bronchoscopy catheterization dialysis intubation ventilation tracheostomy transfusion").split()


def _pseudo_words(rng: np.random.Generator, n: int, taken: set[str]) -> list[str]:
    out: list[str] = []
    syl, fin = np.array(SYLLABLES), np.array(FINAL_SYLLABLES)
    while len(out) < n:
        k = int(rng.integers(1, 4))
        w = "".join(syl[rng.integers(0, len(syl), k)]) + fin[int(rng.integers(0, len(fin)))]
        if w not in taken:
            taken.add(w)
            out.append(w)
    return out


def _one_per_stem(words: list[str]) -> list[str]:
    """Keep the first word of each stem ("state"/"states" -> "state") so no stemmer merges words."""
    from kb_service.analysis import build_analyzer

    an = build_analyzer()
    seen, out = set(), []
    for w in dict.fromkeys(words):
        key = tuple(an.analyze(w)) or (w,)
        if key not in seen:
            seen.add(key)
            out.append(w)
    return out


def _medical_terms() -> list[str]:
    terms = list(MED_TERMS)
    for r in MED_ROOTS:
        for s in MED_SUFFIXES:
            terms.append(r + s)
    for p in MED_PREFIXES:
        for r in MED_ROOTS[:40]:
            terms.append(p + r + "ia")
    return _one_per_stem(terms)


class Generator:
    def __init__(self, seed: int = 0, n_english: int = 30_000, n_topics: int = 2_000) -> None:
        self.rng = np.random.default_rng(seed)
        taken = set(COMMON_ENGLISH)
        common = _one_per_stem(COMMON_ENGLISH)
        self.english = np.array(common + _pseudo_words(self.rng, n_english - len(common), taken), dtype=object)
        ranks = np.arange(1, len(self.english) + 1)
        w = 1.0 / (ranks + 2.7) ** 1.0
        self.eng_cdf = np.cumsum(w / w.sum())
        self.medical = np.array(_medical_terms(), dtype=object)
        mw = 1.0 / np.arange(1, len(self.medical) + 1) ** 0.8
        self.rng.shuffle(mw)
        self.med_cdf = np.cumsum(mw / mw.sum())
        self.topics = self.rng.integers(0, len(self.medical), size=(n_topics, 8))
        self.sources = np.array(["medcpt_evidence", "biomedical_qa", "generator", "medinstruct"], dtype=object)
        self.source_cdf = np.cumsum([0.70, 0.15, 0.10, 0.05])

    def _draw(self, cdf: np.ndarray, n: int) -> np.ndarray:
        return np.minimum(np.searchsorted(cdf, self.rng.random(n)), len(cdf) - 1)

    def _words(self, topic: np.ndarray, n: int, med_frac: float) -> list[str]:
        eng = self.english[self._draw(self.eng_cdf, n)]
        is_med = self.rng.random(n) < med_frac
        n_med = int(is_med.sum())
        if n_med:
            from_topic = self.rng.random(n_med) < 0.7
            med_ids = np.where(from_topic, topic[self.rng.integers(0, topic.shape[0], n_med)],
                               self._draw(self.med_cdf, n_med))
            eng[is_med] = self.medical[med_ids]
        return eng.tolist()

    def passages(self, n: int):
        for i in range(n):
            topic = self.topics[int(self.rng.integers(0, len(self.topics)))]
            length = int(self.rng.integers(60, 251))
            words = self._words(topic, length, 0.15)
            n_tail = int(self.rng.poisson(1.0))
            for _ in range(n_tail):  # rare-token tail: codes, misspellings, identifiers
                words[int(self.rng.integers(0, length))] = "x" + np.base_repr(int(self.rng.integers(0, 36 ** 6)), 36).lower()
            title = " ".join(self.medical[topic[:3]].tolist() + self._words(topic, 2, 0.0)).capitalize()
            src = self.sources[int(np.searchsorted(self.source_cdf, self.rng.random()))]
            yield {"doc_id": f"syn{i:07d}", "source": src, "title": title, "content": " ".join(words) + ".",
                   "category": f"topic{int(topic[0]) % 50}", "dataset_name": "synthetic"}

    def queries(self, n: int) -> list[str]:
        out = []
        for _ in range(n):
            topic = self.topics[int(self.rng.integers(0, len(self.topics)))]
            total = int(self.rng.integers(3, 13))
            n_med = int(self.rng.integers(1, min(5, total) + 1))
            words = self.medical[topic[self.rng.integers(0, topic.shape[0], n_med)]].tolist()
            words += self._words(topic, total - n_med, 0.0)
            self.rng.shuffle(words)
            out.append(" ".join(words))
        return out


# The "pubmed" profile: passages with the length of MedRAG's PubMed snippets and a Zipf vocabulary.
# * Length: MedRAG's corpus table gives PubMed's 23.9M snippets (one per abstract: title and
#   abstract) an average length of 296 words (github.com/Teddy-XiongGZ/MedRAG, "Corpus"). Here a
#   title of 8-16 words (mean 12) and an abstract of log-normal length with mean 284 words, so
#   a passage averages 296 words. The spread (sigma 0.5, clipped to 20-2,000 words) is our
#   choice: the table gives only the mean.
# * Vocabulary: Zipf's law with exponent 1 (word frequency ~ 1/(rank + 2.7), the Zipf-Mandelbrot
#   form of the default profile) over 1,000,000 words: the 390 common English words, then
#   generated pseudo-words; 15% of the words replaced by medical terms clustered in 2,000
#   topics; a tail of about one code-like token per passage (Poisson, mean 1), so the
#   vocabulary keeps growing with the corpus as PubMed's (identifiers, gene and chemical names)
#   does. Stop words are drawn like any word (they are the Zipf head) and dropped by every
#   engine's analyzer, as in real abstracts.
PUBMED_TITLE_WORDS = (8, 16)
PUBMED_CONTENT_MEAN = 284
PUBMED_SIGMA = 0.5
PUBMED_VOCAB = 1_000_000


class PubMedGenerator(Generator):
    """The "pubmed" profile (see above). Every seed shares one vocabulary and one set of topics
    (drawn with seed 0), so the queries of seed + 1 use the corpus's words."""

    def __init__(self, seed: int = 0, n_english: int = PUBMED_VOCAB, n_topics: int = 2_000) -> None:
        super().__init__(0, n_english=n_english, n_topics=n_topics)
        self.rng = np.random.default_rng([seed, 1])

    def passages(self, n: int, block: int = 2000):
        rng = self.rng
        mu = np.log(PUBMED_CONTENT_MEAN) - PUBMED_SIGMA ** 2 / 2  # a log-normal of mean PUBMED_CONTENT_MEAN
        done = 0
        while done < n:
            b = min(block, n - done)
            topic_ids = rng.integers(0, len(self.topics), b)
            lens = np.clip(np.rint(rng.lognormal(mu, PUBMED_SIGMA, b)), 20, 2000).astype(np.int64)
            title_lens = rng.integers(PUBMED_TITLE_WORDS[0], PUBMED_TITLE_WORDS[1] + 1, b)
            words = self.english[self._draw(self.eng_cdf, int(lens.sum()))]
            is_med = rng.random(len(words)) < 0.15
            n_med = int(is_med.sum())
            doc_of = np.repeat(np.arange(b), lens)[is_med]
            in_topic = self.topics[topic_ids[doc_of], rng.integers(0, self.topics.shape[1], n_med)]
            words[is_med] = self.medical[np.where(rng.random(n_med) < 0.7, in_topic, self._draw(self.med_cdf, n_med))]
            title_words = self.english[self._draw(self.eng_cdf, int((title_lens - 3).sum()))].tolist()
            words = words.tolist()
            tails = rng.poisson(1.0, b)
            at = t_at = 0
            for j in range(b):
                i = done + j
                body = words[at:at + lens[j]]
                at += lens[j]
                for _ in range(int(tails[j])):  # rare-token tail: codes, identifiers
                    body[int(rng.integers(0, len(body)))] = "x" + np.base_repr(int(rng.integers(0, 36 ** 6)), 36).lower()
                topic = self.topics[topic_ids[j]]
                title = " ".join(self.medical[topic[:3]].tolist() + title_words[t_at:t_at + title_lens[j] - 3])
                t_at += title_lens[j] - 3
                src = self.sources[int(np.searchsorted(self.source_cdf, rng.random()))]
                yield {"doc_id": f"pm{i:08d}", "source": src, "title": title.capitalize(), "content": " ".join(body) + ".",
                       "category": f"topic{int(topic[0]) % 50}", "dataset_name": "synthetic-pubmed"}
            done += b


PROFILES = {"medical": Generator, "pubmed": PubMedGenerator}


def make_corpus(workdir: Path, n: int, n_queries: int, seed: int, profile: str = "medical",
                gzip_corpus: bool = False, need_corpus: bool = True) -> tuple[Path, list[str]]:
    gen_cls = PROFILES[profile]
    tag = "" if profile == "medical" else f"{profile}-"
    corpus = workdir / f"corpus-{tag}{n}-{seed}.jsonl{'.gz' if gzip_corpus else ''}"
    qfile = workdir / f"queries-{tag}{n}-{n_queries}-{seed}.json"
    gen = gen_cls(seed)
    if need_corpus and not corpus.exists():
        t = time.perf_counter()
        tmp = corpus.with_name(corpus.name + ".tmp")
        # gzip level 1: about half the JSONL's size (random Zipf words compress poorly) for little CPU;
        # at 10M passages the plain corpus is ~23 GB beside a ~53 GB index.
        opener = (lambda path: gzip.open(path, "wt", encoding="utf-8", compresslevel=1)) if gzip_corpus else (
            lambda path: open(path, "w", encoding="utf-8"))
        with opener(tmp) as fh:
            for p in gen.passages(n):
                fh.write(json.dumps(p) + "\n")
        os.replace(tmp, corpus)
        print(f"[bench] corpus: {n:,} passages in {time.perf_counter() - t:.0f}s -> {corpus}", flush=True)
    queries = gen_cls(seed + 1).queries(n_queries)
    qfile.write_text(json.dumps(queries))
    return corpus, queries


def iter_corpus(path: Path):
    with (gzip.open(path, "rt", encoding="utf-8") if path.name.endswith(".gz") else open(path, encoding="utf-8")) as fh:
        for line in fh:
            yield json.loads(line)


# ---------------------------------------------------------------------------------------------
# Engines
# ---------------------------------------------------------------------------------------------


class Ours:
    name = "ours"

    @staticmethod
    def build(corpus: Path, index: Path) -> None:
        from kb_service.ingest import build_kb, file_input

        budget = os.environ.get("HCGYM_BENCH_KB_BUDGET_MB")
        workers = os.environ.get("HCGYM_BENCH_KB_WORKERS")
        drop_corpus = os.environ.get("HCGYM_BENCH_DROP_CORPUS") == "1"
        t0 = time.perf_counter()

        def echo(line: str) -> None:
            # --kb-workers / --build-workers: the build's progress lines on stderr, timed, to split the
            # index stage.
            if workers:
                print(f"[{time.perf_counter() - t0:7.1f}s] {line}", file=sys.stderr, flush=True)
            if drop_corpus and line.startswith("[kb] ingest done:"):
                corpus.unlink()
                print(f"[{time.perf_counter() - t0:7.1f}s] [bench] corpus {corpus.name} deleted after the ingest "
                      f"(--drop-corpus-after-ingest)", file=sys.stderr, flush=True)
        return build_kb([file_input(corpus)], index, progress=False, resume=False, echo=echo,
                        memory_budget_mb=int(budget) if budget else None,
                        workers=int(workers) if workers else None)

    # One KnowledgeBase per index in a query process: `ours` and `ours-rank` query the same KB, as
    # one replica serves both calls (two copies of a 10M-passage KB's vocabularies, 6.3 GB each,
    # would leave the page cache too little of the index).
    _opened: dict[Path, object] = {}

    def __init__(self, index: Path) -> None:
        from kb_service.kb import KnowledgeBase

        key = Path(index).resolve()
        if key not in Ours._opened:
            Ours._opened[key] = KnowledgeBase.open(index)
        self.kb = Ours._opened[key]

    def search(self, q: str) -> list[str]:
        return [p.doc_id for p in self.kb.search(q, k=K)]


class OursRank(Ours):
    """Our KB's ranking alone (`KnowledgeBase.rank`), ids mapped from memory like the bm25s baseline."""

    name = "ours-rank"

    def __init__(self, index: Path) -> None:
        super().__init__(index)
        import sqlite3

        db = sqlite3.connect(f"file:{index / 'passages.sqlite'}?mode=ro", uri=True)
        self.ids = [r[0] for r in db.execute("SELECT doc_id FROM passages ORDER BY rowid")]
        db.close()

    def search(self, q: str) -> list[str]:
        return [self.ids[d] for d, _s in self.kb.rank(q, k=K)]


class BM25S:
    name = "bm25s"

    @staticmethod
    def build(corpus: Path, index: Path) -> None:
        import bm25s
        from bm25s.tokenization import Tokenized, Tokenizer

        # bm25s's Tokenizer over a stream of texts (the same splitter and stop words as
        # bm25s.tokenize), so that the texts themselves are never all in memory at once.
        ids: list[str] = []

        def texts():
            for d in iter_corpus(corpus):
                ids.append(d["doc_id"])
                yield f"{d['title']}\n{d['content']}"

        tokenizer = Tokenizer(stopwords="en")
        token_ids = tokenizer.tokenize(texts(), return_as="ids", show_progress=False, length=0)
        tokens = Tokenized(ids=token_ids, vocab=tokenizer.get_vocab_dict())
        del token_ids
        retriever = bm25s.BM25(k1=1.2, b=0.75, method="lucene", backend="numba")
        retriever.index(tokens, show_progress=False)
        retriever.save(str(index), show_progress=False)
        (index / "doc_ids.json").write_text(json.dumps(ids))

    def __init__(self, index: Path) -> None:
        import bm25s

        self.bm25s = bm25s
        self.r = bm25s.BM25.load(str(index), mmap=True, show_progress=False)
        self.ids = json.loads((index / "doc_ids.json").read_text())

    def search(self, q: str) -> list[str]:
        toks = self.bm25s.tokenize([q], stopwords="en", show_progress=False, return_ids=False)
        toks = [[t for t in dict.fromkeys(toks[0]) if t in self.r.vocab_dict]]  # de-duplicated, as every engine
        if not toks[0]:
            return []
        docs, scores = self.r.retrieve(toks, k=K, n_threads=1, show_progress=False)
        return [self.ids[d] for d, s in zip(docs[0], scores[0]) if s > 0]


def _tantivy_analyzer():
    import tantivy

    return (tantivy.TextAnalyzerBuilder(tantivy.Tokenizer.simple()).filter(tantivy.Filter.remove_long(40))
            .filter(tantivy.Filter.lowercase()).filter(tantivy.Filter.stemmer("english")).build())


class Tantivy:
    name = "tantivy"

    @staticmethod
    def build(corpus: Path, index: Path) -> None:
        import tantivy

        sb = tantivy.SchemaBuilder()
        sb.add_text_field("doc_id", stored=True, tokenizer_name="raw")
        sb.add_text_field("text", stored=True, tokenizer_name="en")
        index.mkdir(parents=True, exist_ok=True)
        idx = tantivy.Index(sb.build(), path=str(index), reuse=False)
        idx.register_tokenizer("en", _tantivy_analyzer())
        w = idx.writer(heap_size=256_000_000)
        for d in iter_corpus(corpus):
            doc = tantivy.Document()
            doc.add_text("doc_id", d["doc_id"])
            doc.add_text("text", f"{d['title']}\n{d['content']}")
            w.add_document(doc)
        w.commit()
        w.wait_merging_threads()

    def __init__(self, index: Path) -> None:
        import tantivy

        self.t = tantivy
        self.idx = tantivy.Index.open(str(index))
        self.idx.register_tokenizer("en", _tantivy_analyzer())
        self.an = _tantivy_analyzer()
        self.schema = self.idx.schema
        self.searcher = self.idx.searcher()

    def search(self, q: str) -> list[str]:
        t = self.t
        words = [w for w in dict.fromkeys(re.findall(r"[^\W_]+", q.lower())) if w not in STOPWORDS]
        terms = list(dict.fromkeys(x for w in words for x in self.an.analyze(w)))
        if not terms:
            return []
        query = t.Query.boolean_query([(t.Occur.Should, t.Query.term_query(self.schema, "text", x)) for x in terms])
        hits = self.searcher.search(query, K, count=False).hits
        return [self.searcher.doc(addr)["doc_id"][0] for _s, addr in hits]


def fts5_query(q: str) -> str:
    """The safe FTS5 query builder: each lower-cased word as a quoted string, OR-ed."""
    words = [w for w in dict.fromkeys(re.findall(r"[^\W_]+", q.lower())) if w not in STOPWORDS]
    return " OR ".join('"' + w.replace('"', '""') + '"' for w in words)


class FTS5:
    name = "fts5"

    @staticmethod
    def build(corpus: Path, index: Path) -> None:
        import sqlite3

        index.mkdir(parents=True, exist_ok=True)
        db = sqlite3.connect(index / "kb.sqlite")
        db.execute("PRAGMA journal_mode=OFF")
        db.execute("PRAGMA synchronous=OFF")
        db.execute("CREATE VIRTUAL TABLE passages_fts USING fts5(doc_id, source, title, content, category, "
                   "dataset_name, tokenize='porter unicode61')")
        batch = []
        for d in iter_corpus(corpus):
            batch.append((d["doc_id"], d["source"], d["title"], d["content"], d["category"], d["dataset_name"]))
            if len(batch) >= 10_000:
                db.executemany("INSERT INTO passages_fts VALUES (?,?,?,?,?,?)", batch)
                batch = []
        db.executemany("INSERT INTO passages_fts VALUES (?,?,?,?,?,?)", batch)
        db.execute("INSERT INTO passages_fts(passages_fts) VALUES('optimize')")
        db.commit()
        db.close()

    def __init__(self, index: Path) -> None:
        import sqlite3

        self.db = sqlite3.connect(f"file:{index / 'kb.sqlite'}?mode=ro", uri=True)

    def search(self, q: str) -> list[str]:
        expr = fts5_query(q)
        if not expr:
            return []
        rows = self.db.execute("SELECT doc_id FROM passages_fts WHERE passages_fts MATCH ? "
                               "ORDER BY bm25(passages_fts) LIMIT ?", (expr, K)).fetchall()
        return [r[0] for r in rows]


ENGINES = {e.name: e for e in (Ours, OursRank, FTS5, Tantivy, BM25S)}


# ---------------------------------------------------------------------------------------------
# Measurement
# ---------------------------------------------------------------------------------------------


def _build_worker(engine: str, corpus: str, index: str) -> None:
    t = time.perf_counter()
    summary = ENGINES[engine].build(Path(corpus), Path(index))
    out = {"build_s": time.perf_counter() - t}
    if isinstance(summary, dict) and summary.get("bm25_shards"):
        out["bm25_shards"] = summary["bm25_shards"]
        out["stage_s"] = summary.get("seconds")
    print(json.dumps(out))


def _available_bytes() -> int:
    with open("/proc/meminfo") as fh:
        info = dict(line.split(":", 1) for line in fh)
    return int(info["MemAvailable"].split()[0]) * 1024


def build_engine(engine: str, corpus: Path, index: Path, budget_mb: int | None = None,
                 cap_bytes: int | None = None, workers: int | None = None, drop_corpus: bool = False) -> dict:
    """Build in a child process: its build time, peak RSS (wait4) and size on disk. `cap_bytes`
    limits the child's address space, so that an engine that would need more memory than the
    machine has fails with a MemoryError instead of waking the OOM killer on a shared machine."""
    if index.exists():
        shutil.rmtree(index)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    if budget_mb:
        env["HCGYM_BENCH_KB_BUDGET_MB"] = str(budget_mb)
    if workers:
        env["HCGYM_BENCH_KB_WORKERS"] = str(workers)
    if drop_corpus:
        env["HCGYM_BENCH_DROP_CORPUS"] = "1"
    limit = None
    if cap_bytes:
        import resource

        limit = lambda: resource.setrlimit(resource.RLIMIT_AS, (cap_bytes, cap_bytes))  # noqa: E731
    # Started through a small launcher that measures it: Linux counts in a child's ru_maxrss the
    # high-water mark of the process it was started from (here this one, with the corpus
    # generator's vocabulary), so measured from here every build would peak at least at ours.
    launch = ("import json, os, subprocess, sys\nproc = subprocess.Popen(sys.argv[1:])\n"
              "_pid, status, usage = os.wait4(proc.pid, 0)\n"
              "print(json.dumps({'rc': os.waitstatus_to_exitcode(status), 'maxrss_kb': usage.ru_maxrss,\n"
              "                  'cpu_s': usage.ru_utime + usage.ru_stime}))\n")
    proc = subprocess.Popen([sys.executable, "-c", launch, sys.executable, __file__, "--worker-build", engine,
                             str(corpus), str(index)], stdout=subprocess.PIPE, env=env, preexec_fn=limit)
    out, _ = proc.communicate()
    lines = out.decode().strip().splitlines()
    measured = json.loads(lines[-1]) if lines and lines[-1].startswith("{\"rc\"") else {"rc": proc.returncode}
    proc.returncode = measured["rc"] or proc.returncode
    if proc.returncode != 0:
        raise RuntimeError(f"building {engine} failed (exit {proc.returncode}"
                           + (f"; address space capped at {cap_bytes / 1024 ** 3:.1f} GB)" if cap_bytes else ")"))
    res = json.loads(lines[-2])
    res["peak_rss_gb"] = measured["maxrss_kb"] / 1024 ** 2
    res["cpu_s"] = measured.get("cpu_s")  # user + system of the build and every process it waited for
    res["disk_gb"] = sum(f.stat().st_size for f in index.rglob("*") if f.is_file()) / 1024 ** 3
    return res


def _query_worker(specs: list[tuple[str, str]], queries: list[str], subsets: dict[str, list[int]], block: int,
                  barrier, results) -> None:
    """Run every engine over the queries in interleaved blocks, so that background load on a
    shared machine falls on all engines alike; with 2 processes both run the same engine block
    at the same time (a barrier before each block)."""
    engines = {name: ENGINES[name](Path(index)) for name, index in specs}
    # Warm-up, untimed: every query once (numba compilation, the page cache holding each engine's
    # index, SQLite's caches), so the timed passes compare engines in their steady state rather
    # than whichever engine happened to be read from disk first.
    for name, eng in engines.items():
        for i in subsets[name]:
            eng.search(queries[i])
    out = {name: {"lat": [], "tops": [], "blocks": []} for name in engines}
    for b0 in range(0, len(queries), block):
        for name, eng in engines.items():
            ids = [i for i in subsets[name] if b0 <= i < b0 + block]
            barrier.wait()
            t0 = time.perf_counter()
            for i in ids:
                t = time.perf_counter()
                out[name]["tops"].append(eng.search(queries[i]))
                out[name]["lat"].append(time.perf_counter() - t)
            out[name]["blocks"].append(time.perf_counter() - t0)
    results.put(out)


def run_queries(specs: list[tuple[str, Path]], queries: list[str], subsets: dict[str, list[int]], procs: int,
                block: int = 50) -> list[dict]:
    ctx = mp.get_context("spawn")
    barrier = ctx.Barrier(procs)
    results = ctx.Queue()
    args = ([(n, str(p)) for n, p in specs], queries, subsets, block, barrier, results)
    ps = [ctx.Process(target=_query_worker, args=args) for _ in range(procs)]
    for p in ps:
        p.start()
    out = [results.get() for _ in ps]
    for p in ps:
        p.join()
        if p.exitcode != 0:
            raise RuntimeError(f"query worker failed (exit {p.exitcode})")
    return out


def overlap(a: list[list[str]], b: list[list[str]]) -> float:
    vals = [len(set(x) & set(y)) / max(1, min(K, len(y))) for x, y in zip(a, b) if y]
    return float(np.mean(vals)) if vals else float("nan")


def bench_pages(work: Path, n: int, seed: int) -> dict:
    """Article store: ingest rate, bytes per article, lookup latency by title (random order)."""
    from kb_service.pages import PageStore, PageStoreWriter

    gen = Generator(seed + 3)
    rng = np.random.default_rng(seed + 4)
    store = work / f"pages-{n}"
    shutil.rmtree(store, ignore_errors=True)
    titles, raw = [], 0
    t = time.perf_counter()
    w = PageStoreWriter(store)
    pool = list(gen.passages(20_000))
    for i in range(n):
        picks = rng.integers(0, len(pool), int(rng.integers(3, 25)))  # 3-24 paragraphs of ~155 words
        text = "\n\n".join(pool[j]["content"] for j in picks)
        title = f"{pool[picks[0]]['title']} {i}"
        titles.append(title)
        raw += len(text.encode())
        w.add(title, text, f"https://example.org/wiki/{i}")
    w.close()
    build_s = time.perf_counter() - t
    ps = PageStore(store)
    order = rng.permutation(n)[:2000]
    lat = []
    for i in order:
        t = time.perf_counter()
        art = ps.get(titles[i])
        lat.append(time.perf_counter() - t)
        assert art is not None
    disk = {f.name: f.stat().st_size for f in store.iterdir()}
    shutil.rmtree(store, ignore_errors=True)
    return {"articles": n, "build_s": build_s, "articles_per_s": n / build_s, "raw_text_gb": raw / 1024 ** 3,
            "data_gb": disk["pages.zlib"] / 1024 ** 3, "index_gb": disk["pages.sqlite"] / 1024 ** 3,
            "bytes_per_article_index": disk["pages.sqlite"] / n, "compression": raw / disk["pages.zlib"],
            "lookup_p50_ms": float(np.percentile(lat, 50) * 1000), "lookup_p99_ms": float(np.percentile(lat, 99) * 1000)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n-passages", default=str(PAPER_N),
                    help="corpus size, or sizes separated by commas (each measured in turn: a scaling curve)")
    ap.add_argument("--profile", choices=sorted(PROFILES), default="medical",
                    help="corpus generator: medical (60-250 words, the default) or pubmed (MedRAG PubMed snippet "
                    "length, Zipf vocabulary; see PubMedGenerator)")
    ap.add_argument("--n-queries", type=int, default=1000)
    ap.add_argument("--fts5-sample", type=int, default=100,
                    help="FTS5 is timed on this many seeded queries when it would take too long for all")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--engines", default="ours,ours-rank,bm25s,tantivy,fts5")
    ap.add_argument("--memory-budget-mb", type=int, default=None,
                    help="build ours within this memory budget (sharded bm25 index; kb_service/README.md)")
    ap.add_argument("--procs", default="1,2", help="query passes: 1 process, and 2 processes when listed")
    ap.add_argument("--peer-cap-gb", type=float, default=None,
                    help="address-space cap of the peers' build processes (default: available memory less 2 GB)")
    ap.add_argument("--workdir", default=os.environ.get("HCGYM_BENCH_DIR", "/tmp/hcgym-bench-kb"))
    ap.add_argument("--keep", action="store_true", help="keep the built indexes")
    ap.add_argument("--keep-corpus", action="store_true", help="keep the generated corpora (large at 1M+)")
    ap.add_argument("--reuse", action="store_true",
                    help="reuse indexes kept by an earlier --keep run (their recorded build figures are reported)")
    ap.add_argument("--articles", type=int, default=0, help="also measure the article store with this many articles")
    ap.add_argument("--kb-workers", default=None, metavar="N,M",
                    help="measure only our build, once per number of bm25 worker processes listed (build time by "
                    "stage, peak RSS; no queries): the parallel build against the single-process one")
    ap.add_argument("--gzip-corpus", action="store_true",
                    help="write the generated corpus as .jsonl.gz (read as such by every engine; about half the "
                    "size): at 10M passages the plain JSONL is ~23 GB")
    ap.add_argument("--build-workers", type=int, default=None, metavar="N",
                    help="build ours with N worker processes (`hcgym kb build --workers N`) before querying it")
    ap.add_argument("--drop-corpus-after-ingest", action="store_true",
                    help="delete the generated corpus once our build has ingested it (only with --engines among "
                    "ours,ours-rank, which read it no more): at 10M passages the disk holds the index or the corpus "
                    "beside the build's peak, not both")
    args = ap.parse_args(argv)
    sizes = [int(x) for x in str(args.n_passages).split(",") if x.strip()]
    if args.drop_corpus_after_ingest:
        others = sorted({e.strip() for e in args.engines.split(",") if e.strip()} - {"ours", "ours-rank"})
        if others or args.keep_corpus or args.kb_workers:
            ap.error("--drop-corpus-after-ingest needs --engines among ours,ours-rank (it has "
                     f"{', '.join(others) or 'none other'}), and neither --keep-corpus nor --kb-workers")
    if args.kb_workers:
        for n in sizes:
            run_workers(args, n, [int(w) for w in args.kb_workers.split(",")])
        return 0
    curve = {}
    for n in sizes:
        curve[n] = run_size(args, n)
    if len(sizes) > 1 or args.profile != "medical":
        scaling_report(curve, args)
    return 0


def run_workers(args, n_passages: int, counts: list[int]) -> dict:
    """Our build with each number of bm25 workers in `counts`, one after the other on one corpus.

    Peak RSS two ways: wait4 of the build process (Linux gives the largest single process of the
    tree, not a sum) and the build's own account (VmHWM of the build process plus each worker's;
    the sum bounds what they held together)."""
    work = Path(args.workdir)
    work.mkdir(parents=True, exist_ok=True)
    corpus, _queries = make_corpus(work, n_passages, args.n_queries, args.seed, args.profile, args.gzip_corpus)
    results = {}
    for w in counts:
        index = work / f"index-ours-w{w}-{args.profile}-{n_passages}"
        load = os.getloadavg()
        print(f"[bench] ours, {w} worker(s), budget {args.memory_budget_mb} MB: building (load average "
              f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}) ...", flush=True)
        res = build_engine("ours", corpus, index, budget_mb=args.memory_budget_mb, workers=w)
        res["load_before"] = load
        res["load_after"] = os.getloadavg()
        peak = (res.get("bm25_shards") or {}).get("peak_rss_mb")
        res["own_peak_sum_mb"] = peak["main"] + sum(peak["workers"]) if peak else None
        results[w] = res
        print(f"[bench] ours, {w} worker(s): {res['build_s']:.0f}s (stages {res.get('stage_s')}), "
              f"{res['disk_gb']:.2f} GB, "
              f"CPU {res['cpu_s']:.0f}s, peak RSS wait4 {res['peak_rss_gb']:.2f} GB, own account {peak} (load average after "
              f"{res['load_after'][0]:.1f})", flush=True)
        if not args.keep:
            shutil.rmtree(index, ignore_errors=True)
    base = results[counts[0]]["build_s"]
    print(f"\n| passages | workers | build | index stage | build peak RSS (wait4) | main + workers' own peaks | "
          f"time vs {counts[0]} worker(s) |")
    print("|---|---|---|---|---|---|---|")
    for w, r in results.items():
        own = f"{r['own_peak_sum_mb']} MB" if r["own_peak_sum_mb"] else "-"
        print(f"| {n_passages:,} | {w} | {r['build_s']:.0f} s | {(r.get('stage_s') or {}).get('index', '-')} s | "
              f"{r['peak_rss_gb']:.2f} GB | {own} | {r['build_s'] / base:.2f}x |")
    out = work / f"results-workers-{args.profile}-{n_passages}.json"
    out.write_text(json.dumps({str(k): v for k, v in results.items()}, indent=2))
    print(f"[bench] results -> {out}", flush=True)
    if not args.keep_corpus:
        corpus.unlink(missing_ok=True)
    return results


def run_size(args, n_passages: int) -> dict:
    work = Path(args.workdir)
    work.mkdir(parents=True, exist_ok=True)
    load = os.getloadavg()
    t_size = time.perf_counter()
    print(f"[bench] {n_passages:,} passages ({args.profile} profile), {args.n_queries} queries, seed {args.seed}, "
          f"{os.cpu_count()} CPUs, load average {load[0]:.1f}", flush=True)
    engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    tag = "" if args.profile == "medical" else f"{args.profile}-"
    # --reuse with every index kept: the queries alone (a 10M corpus takes ~16 minutes to generate).
    kept = args.reuse and all((work / f"index-{name}-{tag}{n_passages}" / "bench-build.json").is_file()
                              for name in engines if name != "ours-rank")
    corpus, queries = make_corpus(work, n_passages, args.n_queries, args.seed, args.profile, args.gzip_corpus,
                                  need_corpus=not kept)
    rng = np.random.default_rng(args.seed + 2)
    results: dict[str, dict] = {}
    specs: list[tuple[str, Path]] = []
    for name in engines:
        if name == "ours-rank" and "failed" in results.get("ours", {}):
            continue
        if name == "ours-rank" and "ours" in results:  # same index as ours: the ranking alone
            index = work / f"index-ours-{tag}{n_passages}"
            res = {k: results["ours"][k] for k in ("build_s", "peak_rss_gb", "disk_gb")}
        else:
            index = work / f"index-{name}-{tag}{n_passages}"
            recorded = index / "bench-build.json"
            if args.reuse and recorded.is_file():
                res = json.loads(recorded.read_text())
                print(f"[bench] {name}: reusing {index}", flush=True)
            else:
                budget = args.memory_budget_mb if name == "ours" else None
                cap = None
                if name in ("bm25s", "tantivy", "fts5"):
                    cap = int((args.peer_cap_gb * 1024 ** 3) if args.peer_cap_gb else _available_bytes() - 2 * 1024 ** 3)
                print(f"[bench] {name}: building" + (f" within a {budget} MB budget" if budget else "")
                      + (f" (address space capped at {cap / 1024 ** 3:.1f} GB)" if cap else "") + " ...", flush=True)
                try:
                    res = build_engine(name, corpus, index, budget_mb=budget, cap_bytes=cap,
                                       workers=args.build_workers if name == "ours" else None,
                                       drop_corpus=args.drop_corpus_after_ingest and name == "ours")
                except RuntimeError as exc:
                    print(f"[bench] {name}: {exc}; left out at this size", flush=True)
                    shutil.rmtree(index, ignore_errors=True)
                    results[name] = {"failed": str(exc)}
                    continue
                recorded.write_text(json.dumps(res))
            print(f"[bench] {name}: built in {res['build_s']:.0f}s, {res['disk_gb']:.2f} GB, peak RSS "
                  f"{res['peak_rss_gb']:.2f} GB (load average {os.getloadavg()[0]:.1f})", flush=True)
        results[name] = res
        specs.append((name, index))
    failed = {name: r for name, r in results.items() if "failed" in r}
    for name in failed:
        del results[name]
    engines = [name for name, _ in specs]

    all_ids = list(range(len(queries)))
    subsets = {name: all_ids for name in engines}
    if "fts5" in engines and n_passages > 100_000 and args.fts5_sample < len(queries):
        subsets["fts5"] = np.sort(rng.choice(len(queries), args.fts5_sample, replace=False)).tolist()
        results["fts5"]["query_sample"] = subsets["fts5"]
    procs = [int(p) for p in str(args.procs).split(",")]
    print(f"[bench] querying, engines interleaved in blocks of 50 queries: 1 process ...", flush=True)
    one = run_queries(specs, queries, subsets, 1)[0]
    two = None
    if 2 in procs:
        print(f"[bench] 2 processes ... (load average {os.getloadavg()[0]:.1f})", flush=True)
        two = run_queries(specs, queries, subsets, 2)
    for name in engines:
        res = results[name]
        qs = [queries[i] for i in subsets[name]]
        lat = np.array(one[name]["lat"]) * 1000
        res.update(n_queries=len(qs), p50_ms=float(np.percentile(lat, 50)), p99_ms=float(np.percentile(lat, 99)),
                   mean_ms=float(lat.mean()), qps_1=len(qs) / sum(one[name]["blocks"]), tops=one[name]["tops"],
                   queries=qs)
        if two is not None:
            block_max = np.max([r[name]["blocks"] for r in two], axis=0)
            res["qps_2"] = 2 * len(qs) / float(block_max.sum())
            res["scaling_2"] = res["qps_2"] / res["qps_1"]
        print(f"[bench] {name}: p50 {res['p50_ms']:.2f} ms, p99 {res['p99_ms']:.2f} ms, {res['qps_1']:.1f} q/s "
              f"(1 proc)" + (f", {res['qps_2']:.1f} q/s (2 procs)" if two is not None else ""), flush=True)
    if not args.keep:
        for _name, index in specs:
            shutil.rmtree(index, ignore_errors=True)
    if not args.keep_corpus and args.profile != "medical":
        corpus.unlink(missing_ok=True)

    if "bm25s" in results:
        ref = dict(zip(results["bm25s"]["queries"], results["bm25s"]["tops"]))
        for name, res in results.items():
            res["overlap_bm25s"] = overlap(res["tops"], [ref[q] for q in res["queries"]])

    report(results, args, load, n_passages, two is not None)
    pages = None
    if args.articles:
        pages = bench_pages(work, args.articles, args.seed)
        print(f"\nArticle store, {pages['articles']:,} articles ({pages['raw_text_gb']:.2f} GB of text): "
              f"{pages['articles_per_s']:.0f} articles/s, data {pages['data_gb']:.2f} GB (x{pages['compression']:.1f} "
              f"compression), index {pages['index_gb']:.3f} GB ({pages['bytes_per_article_index']:.0f} B/article), "
              f"lookup p50 {pages['lookup_p50_ms']:.2f} ms, p99 {pages['lookup_p99_ms']:.2f} ms")
    slim = {n: {k: v for k, v in r.items() if k not in ("tops", "queries")} for n, r in results.items()}
    slim.update(failed)
    out = work / f"results-{tag}{n_passages}.json"
    record = {"n_passages": n_passages, "profile": args.profile, "n_queries": args.n_queries, "seed": args.seed,
              "cpus": os.cpu_count(), "load_before": load, "load_after": os.getloadavg(),
              "memory_budget_mb": args.memory_budget_mb, "seconds": time.perf_counter() - t_size,
              "engines": slim, "article_store": pages}
    out.write_text(json.dumps(record, indent=2))
    print(f"[bench] results: {out}")
    return record


def scaling_report(curve: dict[int, dict], args) -> None:
    """One row per size and engine, with each figure's ratio to bm25s's at the same size (same run)."""
    print(f"\nScaling ({args.profile} profile; q/s vs bm25s = the engine's q/s over bm25s's at the same size, "
          f"same run; load average before each size in brackets):\n")
    print("| passages | engine | build | build peak RSS | on disk | p50 / p99 | q/s | q/s vs bm25s |")
    print("|---|---|---|---|---|---|---|---|")
    for n, rec in curve.items():
        peer = rec["engines"].get("bm25s", {})
        for name, r in rec["engines"].items():
            if "failed" in r:
                print(f"| {n:,} [{rec['load_before'][0]:.1f}] | {name} | failed: {r['failed']} | | | | | |")
                continue
            ratio = f"{r['qps_1'] / peer['qps_1']:.2f}x" if "qps_1" in peer else "n/a"
            print(f"| {n:,} [{rec['load_before'][0]:.1f}] | {name} | {r['build_s']:.0f} s | {r['peak_rss_gb']:.2f} GB | "
                  f"{r['disk_gb']:.2f} GB | {r['p50_ms']:.2f} / {r['p99_ms']:.2f} ms | {r['qps_1']:.0f} | {ratio} |")
    sizes = sorted(curve)
    if len(sizes) > 1 and "ours" in curve[sizes[0]]["engines"] and "ours" in curve[sizes[-1]]["engines"]:
        a, b = curve[sizes[0]]["engines"]["ours"], curve[sizes[-1]]["engines"]["ours"]
        if "build_s" in a and "build_s" in b:
            x = sizes[-1] / sizes[0]
            print(f"\nours from {sizes[0]:,} to {sizes[-1]:,} passages (x{x:.0f}): "
                  f"build time x{b['build_s'] / a['build_s']:.1f}, "
                  f"peak RSS x{b['peak_rss_gb'] / a['peak_rss_gb']:.2f}, size x{b['disk_gb'] / a['disk_gb']:.1f}, "
                  f"p99 x{b['p99_ms'] / a['p99_ms']:.1f}")


def report(results: dict, args, load, n_passages: int, two_procs: bool) -> None:
    print(f"\n| engine | build | on disk | build peak RSS | p50 / p99 | q/s 1 proc | q/s 2 procs | 2/1 | overlap@10 vs bm25s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, r in results.items():
        note = f" ({r['n_queries']} queries)" if r["n_queries"] != args.n_queries else ""
        two = f"{r['qps_2']:.1f} | {r['scaling_2']:.2f}x" if two_procs else "- | -"
        print(f"| {name}{note} | {r['build_s']:.0f} s | {r['disk_gb']:.2f} GB | {r['peak_rss_gb']:.2f} GB | "
              f"{r['p50_ms']:.2f} / {r['p99_ms']:.2f} ms | {r['qps_1']:.1f} | {two} | "
              f"{r.get('overlap_bm25s', float('nan')):.3f} |")
    if "ours" not in results or args.profile != "medical" or not two_procs:
        return  # the targets below are the paper-size (medical profile, 1 and 2 processes) targets
    # The peers are the other engines; ours-rank is our own ranking without passages (a diagnostic row).
    peers = {n: r for n, r in results.items() if n not in ("ours", "ours-rank")}
    fastest = max(peers, key=lambda n: peers[n]["qps_1"]) if peers else None
    checks = []
    for label, o in (("ours", results["ours"]), ("ours-rank", results.get("ours-rank"))):
        if o is None:
            continue
        if fastest is not None:
            checks.append((f"{label}: q/s >= 0.8x the fastest other engine ({fastest})",
                           o["qps_1"] / peers[fastest]["qps_1"], 0.8))
        if "fts5" in results:
            checks.append((f"{label}: q/s >= 50x SQLite FTS5", o["qps_1"] / results["fts5"]["qps_1"], 50))
        checks += [(f"{label}: p99 <= 20 ms", 20 / max(o["p99_ms"], 1e-9), 1.0),
                   (f"{label}: 2 processes >= 1.6x one", o["scaling_2"], 1.6)]
    o = results["ours"]
    checks += [("build <= 6 min", 360 / o["build_s"], 1.0), ("index + passages <= 3 GB", 3 / o["disk_gb"], 1.0)]
    for name, r in results.items():
        if name != "bm25s" and "overlap_bm25s" in r:
            checks.append((f"{name} overlap@10 with bm25s >= 0.8", r["overlap_bm25s"], 0.8))
    print(f"\nTargets ({n_passages:,} passages; load average before the run {load[0]:.1f}):")
    for label, value, need in checks:
        print(f"  [{'PASS' if value >= need else 'FAIL'}] {label}: {value:.2f} (need >= {need})")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker-build":
        _build_worker(*sys.argv[2:5])
        sys.exit(0)
    sys.exit(main())
