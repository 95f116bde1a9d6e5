// The report page's one control per clip: it plays, pauses and seeks all the clip's videos
// together; the first video is the clock, the others are pulled to it whenever they drift by
// half a frame. sidql/evaluation/page.py embeds this at the end of the page.
function syncPlayer(root){
  const vids=[...root.querySelectorAll('video')]; if(!vids.length) return;
  const fps=+root.dataset.fps, n=+root.dataset.frames, clock=vids[0];
  const btn=root.querySelector('.play'), seek=root.querySelector('.seek'),
        out=root.querySelector('.frame');
  let playing=false;
  const frameOf=t=>Math.max(0,Math.min(n-1,Math.floor(t*fps+1e-6)));
  const show=()=>{const f=frameOf(clock.currentTime); seek.value=f;
    out.textContent='frame '+f+' of 0-'+(n-1);};
  const align=()=>{const t=clock.currentTime;
    for(const v of vids) if(v!==clock && Math.abs(v.currentTime-t)>0.5/fps) v.currentTime=t;};
  function tick(){ if(!playing) return; align(); show(); requestAnimationFrame(tick); }
  function play(){ const t=clock.currentTime; for(const v of vids){v.currentTime=t;}
    Promise.all(vids.map(v=>v.play())).catch(()=>{}); playing=true; btn.textContent='\u23f8';
    requestAnimationFrame(tick); }
  function pause(){ for(const v of vids) v.pause(); playing=false; align(); show();
    btn.textContent='\u25b6'; }
  function goto(f){ pause(); f=Math.max(0,Math.min(n-1,f));
    for(const v of vids) v.currentTime=(f+0.5)/fps; seek.value=f;
    out.textContent='frame '+f+' of 0-'+(n-1); }
  root.syncPlay=play; root.syncPause=pause; root.syncGoto=goto;
  btn.addEventListener('click',()=>playing?pause():play());
  seek.addEventListener('input',()=>goto(+seek.value));
  root.querySelector('.prev').addEventListener('click',()=>goto(frameOf(clock.currentTime)-1));
  root.querySelector('.next').addEventListener('click',()=>goto(frameOf(clock.currentTime)+1));
  root.querySelector('.rate').addEventListener('change',e=>{
    for(const v of vids) v.playbackRate=+e.target.value;});
  for(const v of vids) v.addEventListener('click',()=>playing?pause():play());
  for(const a of root.querySelectorAll('[data-goto]'))
    a.addEventListener('click',e=>{e.preventDefault(); goto(+a.dataset.goto);});
  clock.addEventListener('timeupdate',show);
}
document.querySelectorAll('.clip').forEach(syncPlayer);
